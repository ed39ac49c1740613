// The object dictionary is the one source of register facts: pinned here against the datasheet's
// worked facts, checked for consistency, and compared with what derives from it — the codecs'
// offsets, the SDO mapping, the start-up writes, the simulated module and docs/registers.md.
#include "x20ds1928/object_dictionary.hpp"

#include <catch2/catch.hpp>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include "powerlink/process_image.hpp"
#include "sim/ds1928_module.hpp"
#include "sim/sim_error.hpp"
#include "x20ds1928/sdo_mapping.hpp"

using namespace ds1928;

namespace {
const RegisterInfo& entry(uint16_t reg) {
  const RegisterInfo* r = find_register(reg);
  REQUIRE(r != nullptr);
  return *r;
}
}  // namespace

TEST_CASE("Object dictionary: the datasheet's registers by number, type and default",
          "[registers]") {
  // X20DS1928.md §2.1 and §3.
  CHECK(entry(4180).name == "PositionHW");
  CHECK(entry(4180).type == DataType::UDINT);
  CHECK(entry(4188).name == "PositionLW");
  CHECK(entry(4172).type == DataType::DINT);  // PosTime
  CHECK(entry(4163).type == DataType::SINT);  // PosCycle
  CHECK(entry(683).name == "SDCLifeCount");
  CHECK(entry(261).name == "ErrorInfo");
  CHECK(entry(325).name == "AckErrorInfo");
  CHECK(entry(654).type == DataType::UINT);  // CfO_SystemCyclePrescaler
  CHECK(entry(654).default_value == 2u);
  CHECK(entry(513).default_value == 14u);   // CfO_SlframeGenID: X2X-aligned
  CHECK(entry(389).default_value == 255u);  // ErrorEnableID_1710
  CHECK(entry(1034).default_value == 800u);
  CHECK(entry(1038).default_value == 1200u);
  CHECK(entry(1044).type == DataType::UDINT);  // SinCosQuitTime
  CHECK(entry(1044).default_value == 100000u);
  CHECK(entry(1044).accepts(FunctionModel::Standard).max == 20'000'000u);
  CHECK(entry(1034).accepts(FunctionModel::Standard).max == 1500u);
  CHECK(entry(4097).name == "EnDatMode");
  CHECK(entry(4097).default_value == 0u);  // EnDat interface disabled
  CHECK(entry(4099).direction == RegisterDirection::Command);
  CHECK(entry(4352).name == "EnDatError");
  CHECK(entry(4353).name == "EnDatWarning");
  CHECK(entry(4935).name == "EnDatInfoOK");
  CHECK(entry(4609).name == "OutputMTU");
  CHECK(entry(4611).name == "InputMTU");
  CHECK(entry(4613).name == "FlatstreamMode");
  CHECK(entry(4615).name == "Forward");
  CHECK(entry(4620).name == "ForwardDelay");
  CHECK(entry(4672).name == "InputSequence");
  CHECK(entry(4704).name == "OutputSequence");
  // The families and their numbering rules.
  for (unsigned n = 1; n <= 4; ++n) {
    CHECK(entry(static_cast<uint16_t>(4860 + n * 8)).name == "EnDatInfoCmd01..04");
    CHECK(entry(static_cast<uint16_t>(4860 + n * 8)).size() == 4);
    CHECK(entry(static_cast<uint16_t>(4978 + n * 16)).name == "EnDatInfo01..04");
  }
  for (unsigned n = 0; n <= 15; ++n)
    CHECK(entry(static_cast<uint16_t>(4400 + n)).name == "OperatingParam_00..15");
  for (unsigned n = 4; n <= 47; ++n)
    CHECK(entry(static_cast<uint16_t>(4352 + n)).name == "ParamManuf_04..47");
  for (unsigned n = 1; n <= 63; ++n)
    CHECK(entry(static_cast<uint16_t>(4416 + n)).name == "ParamManufEnDat22_01..63");
  CHECK(find_register(4416) == nullptr);  // ParamManufEnDat22_N runs from N = 1
  for (unsigned n = 1; n <= 15; ++n) {
    CHECK(entry(static_cast<uint16_t>(4672 + n)).name == "RxByte1..15");
    CHECK(entry(static_cast<uint16_t>(4704 + n)).name == "TxByte1..15");
  }
  CHECK(find_register(4860 + 8 + 4) == nullptr);  // between two EnDatInfoCmd members
  CHECK(find_register(4688) == nullptr);          // past RxByte15
  CHECK_FALSE(register_size(1).has_value());
  CHECK(register_size(4479) == 2);
}

TEST_CASE("Object dictionary: cyclic offsets as the datasheet and the process image place them",
          "[registers]") {
  // Datasheet §11.3.2 (function model 254): PositionHW 0–3, PositionLW 4–7, InputSequence 8,
  // RxByte1–5 9–13, ErrorInfo 14, PosCycle 15; OutputSequence 0, TxByte1–5 1–5, AckErrorInfo 6.
  CHECK(fm254::kPositionHw == 0);
  CHECK(fm254::kPositionLw == 4);
  CHECK(fm254::kInputSequence == 8);
  CHECK(fm254::kRxBytes == 9);
  CHECK(fm254::kErrorInfo == 14);
  CHECK(fm254::kPosCycle == 15);
  CHECK(fm254::kOutputSequence == 0);
  CHECK(fm254::kTxBytes == 1);
  CHECK(fm254::kAckErrorInfo == 6);
  CHECK(fm254::kMaxMtu == 5);
  CHECK(entry(4673).members(FunctionModel::BusController) == 5);
  CHECK(entry(4673).members(FunctionModel::Standard) == 15);
  // Function model 254 has neither PosTime nor SDCLifeCount.
  CHECK_FALSE(entry(4172).in_model(FunctionModel::BusController));
  CHECK_FALSE(entry(683).in_model(FunctionModel::BusController));
  // Function model 0 (docs/powerlink.md §Process image): the fixed part of the PRes block ends
  // where the Rx bytes start; the PReq block is OutputSequence, Tx bytes, AckErrorInfo.
  CHECK(fm0::kPositionHw == 0);
  CHECK(fm0::kPosTime == 8);
  CHECK(fm0::kInputSequence == 15);
  CHECK(fm0::kRxBytes == powerlink::kPresModuleFixedSize);
  CHECK(fm0::kOutputSequence == 0);
  CHECK(fm0::kTxBytes == 1);
  CHECK(fm0::kMaxMtu == 15);
  CHECK(powerlink::kPreqModuleFixedSize == 2);  // OutputSequence + AckErrorInfo
}

TEST_CASE("Object dictionary: no two registers share a number, a name or an SDO subindex",
          "[registers]") {
  std::set<uint16_t> numbers;
  std::set<std::string_view> names;
  std::set<unsigned> subindices;
  for (const RegisterInfo& r : object_dictionary()) {
    INFO(r.name);
    CHECK(names.insert(r.name).second);
    CHECK(r.count >= 1);
    CHECK(r.stride >= 1);
    CHECK(r.models != 0);
    CHECK(r.size() >= 1);
    CHECK(r.size() <= 4);  // every register fits an expedited SDO transfer
    if (r.view) {
      // A view reads the bits of a register that exists on its own.
      CHECK(r.sdo_subindex == 0);
      CHECK(r.startup_order == 0);
      continue;
    }
    for (unsigned m = 0; m < r.count; ++m) {
      const auto reg = static_cast<uint16_t>(r.number + m * r.stride);
      CHECK(numbers.insert(reg).second);
      CHECK(find_register(reg) == &r);
      CHECK(r.member(reg) == m);
    }
    if (r.sdo_subindex != 0) {
      CHECK(r.sdo_subindex + r.count - 1 <= 0xFF);
      for (unsigned m = 0; m < r.count; ++m) CHECK(subindices.insert(r.sdo_subindex + m).second);
    }
  }
}

TEST_CASE("Object dictionary: cyclic offsets do not overlap and fit the frames", "[registers]") {
  // Function model 254: 16 input bytes over two CAN objects, 8 output bytes (byte 7 unused).
  std::array<int, 16> can_in{};
  std::array<int, 8> can_out{};
  // Function model 0 at the largest MTU: the PRes block (fixed part + 15 Rx bytes), the PReq
  // block (OutputSequence, 15 Tx bytes, AckErrorInfo after them).
  std::array<int, powerlink::kPresModuleFixedSize + fm0::kMaxMtu> pres{};
  std::array<int, powerlink::kPreqModuleFixedSize + fm0::kMaxMtu> preq{};
  for (const RegisterInfo& r : object_dictionary()) {
    INFO(r.name);
    if (r.view) continue;  // its bytes are another register's
    CHECK(r.cyclic() == (r.fm0_offset != kNoOffset || r.can_offset != kNoOffset));
    if (!r.cyclic()) continue;
    CHECK(r.in_model(FunctionModel::Standard) == (r.fm0_offset != kNoOffset));
    CHECK(r.in_model(FunctionModel::BusController) == (r.can_offset != kNoOffset));
    const bool in = r.direction == RegisterDirection::In;
    if (r.can_offset != kNoOffset) {
      const int bytes = r.members(FunctionModel::BusController) * r.size();
      for (int b = 0; b < bytes; ++b) {
        if (in)
          ++can_in.at(static_cast<std::size_t>(r.can_offset + b));
        else
          ++can_out.at(static_cast<std::size_t>(r.can_offset + b));
      }
    }
    if (r.fm0_offset != kNoOffset) {
      const int at = r.fm0_offset + (r.fm0_after_tx_bytes ? int(fm0::kMaxMtu) : 0);
      const int bytes = r.members(FunctionModel::Standard) * r.size();
      for (int b = 0; b < bytes; ++b) {
        if (in)
          ++pres.at(static_cast<std::size_t>(at + b));
        else
          ++preq.at(static_cast<std::size_t>(at + b));
      }
    }
  }
  for (int n : can_in) CHECK(n == 1);
  for (std::size_t b = 0; b < 7; ++b) CHECK(can_out[b] == 1);
  CHECK(can_out[7] == 0);  // unused
  for (int n : pres) CHECK(n == 1);
  for (int n : preq) CHECK(n == 1);
  // A view covers bytes of the register it reads.
  const RegisterInfo& position = od_entry("Position (DINT view of PositionLW)");
  CHECK(position.fm0_offset == int(fm0::kPositionLw));
  CHECK(position.number == od_entry("PositionLW").number);
}

TEST_CASE("Object dictionary: defaults, accepted values and settings agree", "[registers]") {
  std::set<unsigned> orders;
  for (const RegisterInfo& r : object_dictionary()) {
    INFO(r.name);
    for (FunctionModel fm : {FunctionModel::Standard, FunctionModel::BusController}) {
      const ValueRange v = r.accepts(fm);
      CHECK(v.min <= v.max);
      if (r.default_value) CHECK(v.contains(*r.default_value));
    }
    // The daemon's defaults are values the module takes (function model 254's MTUs are clamped
    // to 5 by the configuration loader).
    if (r.setting != Setting::None && r.setting != Setting::AlwaysOne)
      CHECK(
          r.accepts(FunctionModel::Standard).contains(setting_value(r.setting, ModuleSettings{})));
    if (r.startup_order != 0) {
      CHECK(orders.insert(r.startup_order).second);
      CHECK(r.direction == RegisterDirection::Config);
      CHECK(r.setting != Setting::None);
      CHECK(r.count == 1);
    } else {
      CHECK(r.setting == Setting::None);
    }
  }
  CHECK(orders.size() == kStartupWriteCount);
  CHECK(*orders.rbegin() == kStartupWriteCount);
}

TEST_CASE("Object dictionary: the bus controllers' SDO objects", "[registers][sdo]") {
  // The scheme docs/powerlink.md and docs/canio.md describe: index 0x2000 + slot.
  const SdoMapping mapping;
  auto sub = [&](uint16_t reg) {
    const auto o = mapping.object_for(1, reg);
    REQUIRE(o.has_value());
    CHECK(o->index == 0x2001);
    return unsigned{o->subindex};
  };
  CHECK(sub(reg::kEnDatMode) == 0x01);
  CHECK(sub(reg::kSystemCyclePrescaler) == 0x02);
  CHECK(sub(reg::kSinCosQuitTime) == 0x09);
  CHECK(sub(reg::kEnDatAck) == 0x0F);
  CHECK(sub(reg::kErrorInfo) == 0x10);
  CHECK(sub(reg::kAckErrorInfo) == 0x11);
  CHECK(sub(4868) == 0x12);
  CHECK(sub(4892) == 0x15);
  CHECK(sub(4935) == 0x16);
  CHECK(sub(4994) == 0x17);
  CHECK(sub(5042) == 0x1A);
  CHECK(sub(4352) == 0x20);
  CHECK(sub(4399) == 0x4F);
  CHECK(sub(4400) == 0x50);
  CHECK(sub(4415) == 0x5F);
  CHECK(sub(4417) == 0x61);
  CHECK(sub(4479) == 0x9F);
  CHECK(mapping.object_for(3, reg::kEnDatMode) == SdoObject{0x2003, 0x01});
  CHECK_FALSE(mapping.object_for(0, reg::kEnDatMode));
  CHECK_FALSE(mapping.object_for(1, 4672));  // InputSequence: cyclic only
  // Every member of every register with an object maps back to itself.
  for (const RegisterInfo& r : object_dictionary()) {
    if (r.view || r.sdo_subindex == 0) continue;
    for (unsigned m = 0; m < r.count; ++m) {
      const auto reg = static_cast<uint16_t>(r.number + m * r.stride);
      INFO(r.name << " member " << m);
      const auto o = mapping.object_for(2, reg);
      REQUIRE(o.has_value());
      CHECK(mapping.register_for(*o) == RegisterAddress{2, reg});
    }
  }
  // An override moves one register; its default object no longer answers.
  const SdoMapping moved({{reg::kEnDatMode, {0x3000, 7}}});
  CHECK(moved.object_for(2, reg::kEnDatMode) == SdoObject{0x3001, 7});
  CHECK(moved.register_for({0x3001, 7}) == RegisterAddress{2, reg::kEnDatMode});
  CHECK_FALSE(moved.register_for({0x2002, 0x01}));
}

TEST_CASE("Object dictionary: start-up writes cover every configuration setting, EnDatMode last",
          "[registers]") {
  ModuleSettings s;
  s.output_mtu = 5;
  s.input_mtu = 4;
  s.prescaler = 8;
  const auto writes = startup_writes(s);
  std::set<uint16_t> seen;
  for (const RegisterWrite& w : writes) {
    INFO("register " << w.reg);
    REQUIRE(w.reg != 0);
    CHECK(seen.insert(w.reg).second);
    CHECK(register_size(w.reg) == w.size);
    CHECK(entry(w.reg).direction == RegisterDirection::Config);
  }
  CHECK(writes.back().reg == reg::kEnDatMode);
  CHECK(writes.back().value == s.endat_mode());
  auto value_of = [&](uint16_t r) {
    for (const RegisterWrite& w : writes)
      if (w.reg == r) return w.value;
    FAIL("register " << r << " not written");
    return 0u;
  };
  CHECK(value_of(reg::kOutputMtu) == 5);
  CHECK(value_of(reg::kInputMtu) == 4);
  CHECK(value_of(reg::kSystemCyclePrescaler) == 8);
  CHECK(value_of(reg::kSinCosEnable) == 1);
}

TEST_CASE("Object dictionary: the simulated module powers up with its defaults and sizes",
          "[registers]") {
  for (FunctionModel fm : {FunctionModel::Standard, FunctionModel::BusController}) {
    sim::Ds1928Module m(fm, SimAxisConfig{});
    for (const RegisterInfo& r : object_dictionary()) {
      if (r.direction != RegisterDirection::Config || !r.default_value) continue;
      INFO(r.name);
      uint32_t v = 0xDEAD;
      REQUIRE_FALSE(m.read_register(r.number, r.size(), v));
      CHECK(v == *r.default_value);
      if (r.size() != 4) CHECK(m.read_register(r.number, 4, v));  // wrong size refused
    }
  }
}

TEST_CASE("Object dictionary: the simulated module accepts what the dictionary accepts",
          "[registers]") {
  for (FunctionModel fm : {FunctionModel::Standard, FunctionModel::BusController}) {
    sim::Ds1928Module m(fm, SimAxisConfig{});
    for (const RegisterInfo& r : object_dictionary()) {
      if (r.setting == Setting::None || r.setting == Setting::EnDatMode) continue;
      INFO(r.name << " under function model " << int(fm));
      const ValueRange v = r.accepts(fm);
      CHECK_FALSE(m.write_register(r.number, r.size(), v.max));
      CHECK_FALSE(m.write_register(r.number, r.size(), v.min));
      uint32_t back = 0;
      REQUIRE_FALSE(m.read_register(r.number, r.size(), back));
      CHECK(back == v.min);
      if (v.max < 0xFFFF'FFFFu)
        CHECK(m.write_register(r.number, r.size(), v.max + 1) == sim::SimErrc::out_of_range);
      if (v.min > 0)
        CHECK(m.write_register(r.number, r.size(), v.min - 1) == sim::SimErrc::out_of_range);
    }
  }
}

TEST_CASE("Object dictionary: docs/registers.md holds the dictionary's table",
          "[registers][docs]") {
  std::ifstream f(DS1928_SOURCE_DIR "/docs/registers.md");
  REQUIRE(f.good());
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string doc = ss.str();
  const std::string begin = "<!-- object-dictionary:begin -->\n";
  const std::string end = "<!-- object-dictionary:end -->";
  const auto a = doc.find(begin);
  const auto b = doc.find(end);
  REQUIRE(a != std::string::npos);
  REQUIRE(b != std::string::npos);
  const std::string rendered = object_dictionary_markdown();
  if (std::getenv("DS1928_WRITE_REGISTERS_MD") != nullptr) {
    // Regenerate: DS1928_WRITE_REGISTERS_MD=1 ctest -R x20ds1928_object_dictionary_test
    std::ofstream(DS1928_SOURCE_DIR "/docs/registers.md")
        << doc.substr(0, a + begin.size()) << rendered << doc.substr(b);
    return;
  }
  const std::string table = doc.substr(a + begin.size(), b - a - begin.size());
  INFO(
      "docs/registers.md must hold between its markers exactly the rendering below; "
      "DS1928_WRITE_REGISTERS_MD=1 ctest -R x20ds1928_object_dictionary_test writes it:\n"
      << rendered);
  CHECK(table == rendered);
}
