// POWERLINK's standard-object table (powerlink/standard_objects.hpp): every row well-formed, the
// lookups, and the concise DCF import naming the objects it reports from it.
#include "powerlink/standard_objects.hpp"

#include <catch2/catch.hpp>
#include <set>
#include <utility>

#include "powerlink/concise_dcf.hpp"

using namespace ds1928::powerlink;

TEST_CASE("Standard objects: every row is well-formed and none overlaps another",
          "[powerlink][standard_objects]") {
  std::set<std::pair<uint16_t, uint8_t>> seen;
  for (const StandardObject& o : kStandardObjects) {
    INFO(object_name(o.index, o.sub_first) << " " << o.name);
    // DS 301's communication profile area, and a sub-index range that is one.
    CHECK(o.index >= 0x1000);
    CHECK(o.index <= 0x1FFF);
    CHECK(o.sub_first <= o.sub_last);
    CHECK_FALSE(o.name.empty());
    CHECK_FALSE(o.meaning.empty());
    // The default fits the type; a NumberOfEntries is a constant U8.
    const std::size_t width = type_size(o.type);
    if (o.type == ObjType::kDomain) {
      CHECK(o.default_value == 0);
    } else {
      REQUIRE(width > 0);
      if (width < 8) CHECK(o.default_value < (uint64_t{1} << (8 * width)));
    }
    if (o.name.ends_with("NumberOfEntries") && o.access == ObjAccess::kConst) {
      CHECK(o.sub_first == 0);
      CHECK(o.type == ObjType::kU8);
    }
    // A sub-index belongs to one row only.
    for (unsigned s = o.sub_first; s <= o.sub_last; ++s)
      CHECK(seen.insert({o.index, static_cast<uint8_t>(s)}).second);
    // find_standard_object() finds the row at both ends of its range.
    CHECK(find_standard_object(o.index, o.sub_first) == &o);
    CHECK(find_standard_object(o.index, o.sub_last) == &o);
  }
  // A record's NumberOfEntries says how many entries follow (those the table has).
  for (const StandardObject& o : kStandardObjects) {
    if (o.sub_first != 0 || !o.name.ends_with("NumberOfEntries") || o.access != ObjAccess::kConst)
      continue;
    unsigned last = 0;
    for (const StandardObject& e : kStandardObjects)
      if (e.index == o.index) last = std::max<unsigned>(last, e.sub_last);
    INFO(o.name);
    CHECK(o.default_value == last);
  }
}

TEST_CASE("Standard objects: the named indices and sub-indices are rows of the table",
          "[powerlink][standard_objects]") {
  for (uint16_t index : {obj::kDeviceType,
                         obj::kErrorRegister,
                         obj::kCycleLen,
                         obj::kStoreParam,
                         obj::kRestoreDefParam,
                         obj::kIdentity,
                         obj::kVerifyConfiguration,
                         obj::kRxPdoComm,
                         obj::kRxPdoMapping,
                         obj::kTxPdoComm,
                         obj::kTxPdoMapping,
                         obj::kMnCycTimeExceed,
                         obj::kMnCnLossPResThreshold,
                         obj::kCnLossSoc,
                         obj::kCnLossSoa,
                         obj::kCnLossPReq,
                         obj::kCnCrcError,
                         obj::kLossOfSocTolerance,
                         obj::kConciseDcfList,
                         obj::kExpConfDateList,
                         obj::kExpConfTimeList,
                         obj::kNodeAssignment,
                         obj::kMnDeviceTypeIdList,
                         obj::kMnVendorIdList,
                         obj::kMnProductCodeList,
                         obj::kMnRevisionNoList,
                         obj::kMnSerialNoList,
                         obj::kMnCycleTiming,
                         obj::kMnPReqPayloadLimitList,
                         obj::kPResPayloadLimitList,
                         obj::kMnCnPResTimeout,
                         obj::kCycleTiming}) {
    INFO(object_name(index, 0));
    CHECK((has_standard_index(index, ObjHolder::kCn) || has_standard_index(index, ObjHolder::kMn)));
  }
  const StandardObject* pres =
      find_standard_object(obj::kCycleTiming, obj::kCycleTimingPResActPayload);
  REQUIRE(pres != nullptr);
  CHECK(pres->name == "NMT_CycleTiming_REC.PResActPayloadLimit_U16");
  CHECK(pres->type == ObjType::kU16);
  CHECK(pres->access == ObjAccess::kRw);
  // DS 301's worked values: the identity object's product code is a read-only U32.
  const StandardObject* product = find_standard_object(obj::kIdentity, 2);
  REQUIRE(product != nullptr);
  CHECK(product->meaning == "product code");
  CHECK(product->access == ObjAccess::kRo);
  CHECK(find_standard_object(obj::kIdentity, 5) == nullptr);
  CHECK(find_standard_object(0x2000, 0) == nullptr);  // a device's own object
  CHECK_FALSE(has_standard_index(0x2000, ObjHolder::kCn));
}

TEST_CASE("Concise DCF import names the objects it reports through the table",
          "[powerlink][standard_objects][cdc]") {
  CHECK(standard_name(obj::kRxPdoMapping, 3) == "PDO_RxMappParam_00h_AU64.ObjectMapping");
  CHECK(standard_name(obj::kNodeAssignment, 7) == "NMT_NodeAssignment_AU32");
  CHECK(standard_name(0x2000, 1).empty());
  // A truncated entry of a standard object is named; one of a device object only numbered.
  const std::vector<CdcEntry> pdo{{obj::kTxPdoMapping, 1, {1, 2, 3, 4, 5, 6, 7, 8}}};
  auto bytes = encode_cdc(pdo);
  auto cut = decode_cdc(std::span(bytes).first(bytes.size() - 1));
  REQUIRE_FALSE(cut.ok());
  CHECK_THAT(cut.error->message,
             Catch::Equals("entry 0 (0x1A00/1 PDO_TxMappParam_00h_AU64.ObjectMapping) announces 8 "
                           "data bytes, only 7 remain"));
  const std::vector<CdcEntry> own{{0x2000, 1, {1, 2}}};
  bytes = encode_cdc(own);
  cut = decode_cdc(std::span(bytes).first(bytes.size() - 1));
  REQUIRE_FALSE(cut.ok());
  CHECK_THAT(cut.error->message, Catch::StartsWith("entry 0 (0x2000/1) announces"));
  // The image sizes come from the rows the table names (cycle timing /4, /5).
  const std::vector<CdcEntry> timing{{obj::kCycleTiming, obj::kCycleTimingPReqActPayload, {36, 0}},
                                     {obj::kCycleTiming, obj::kCycleTimingPResActPayload, {40, 0}}};
  const ImageSizes sizes = image_sizes_from_objects(timing);
  CHECK(sizes.preq_size == 36);
  CHECK(sizes.pres_size == 40);
}
