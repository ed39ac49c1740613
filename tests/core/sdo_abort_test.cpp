// The one SDO abort-code table (CiA 301 / EPSG DS 301): every code with its name, the error-code
// round trip, and codes outside the table named as unknown.
#include "core/sdo_abort.hpp"

#include <catch2/catch.hpp>
#include <cstdio>
#include <set>
#include <string>
#include <utility>

using namespace ds1928;

namespace {

// Written out again on purpose: the table must hold exactly these, with the standard's text.
const std::pair<uint32_t, const char*> kExpected[] = {
    {0x0503'0000, "toggle bit not alternated"},
    {0x0504'0000, "SDO protocol timed out"},
    {0x0504'0001, "client/server command specifier not valid or unknown"},
    {0x0504'0002, "invalid block size"},
    {0x0504'0003, "invalid sequence number"},
    {0x0504'0004, "CRC error"},
    {0x0504'0005, "out of memory"},
    {0x0601'0000, "unsupported access to an object"},
    {0x0601'0001, "attempt to read a write only object"},
    {0x0601'0002, "attempt to write a read only object"},
    {0x0602'0000, "object does not exist in the object dictionary"},
    {0x0604'0041, "object cannot be mapped to the PDO"},
    {0x0604'0042, "the number and length of the objects to be mapped would exceed PDO length"},
    {0x0604'0043, "general parameter incompatibility"},
    {0x0604'0047, "general internal incompatibility in the device"},
    {0x0606'0000, "access failed due to a hardware error"},
    {0x0607'0010, "data type does not match, length of service parameter does not match"},
    {0x0607'0012, "data type does not match, length of service parameter too high"},
    {0x0607'0013, "data type does not match, length of service parameter too low"},
    {0x0609'0011, "sub-index does not exist"},
    {0x0609'0030, "invalid value for parameter"},
    {0x0609'0031, "value of parameter written too high"},
    {0x0609'0032, "value of parameter written too low"},
    {0x0609'0036, "maximum value is less than minimum value"},
    {0x060A'0023, "resource not available: SDO connection"},
    {0x0800'0000, "general error"},
    {0x0800'0020, "data cannot be transferred or stored to the application"},
    {0x0800'0021,
     "data cannot be transferred or stored to the application because of local control"},
    {0x0800'0022,
     "data cannot be transferred or stored to the application because of the present device "
     "state"},
    {0x0800'0023, "object dictionary dynamic generation fails or no object dictionary is present"},
    {0x0800'0024, "no data available"},
};

std::string hex(uint32_t code) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08X", code);
  return buf;
}

}  // namespace

TEST_CASE("every CiA 301 abort code is in the table with the standard's name", "[core][sdo]") {
  const auto table = sdo_abort_table();
  REQUIRE(table.size() == std::size(kExpected));
  for (std::size_t i = 0; i < table.size(); ++i) {
    INFO(hex(kExpected[i].first));
    CHECK(table[i].code == kExpected[i].first);
    CHECK(table[i].name == kExpected[i].second);
    CHECK(sdo_abort_known(kExpected[i].first));
    CHECK(sdo_abort_name(kExpected[i].first) == kExpected[i].second);
  }
  std::set<std::string_view> names;
  for (const auto& e : table) names.insert(e.name);
  CHECK(names.size() == table.size());
}

TEST_CASE("the named constants are the codes of the table", "[core][sdo]") {
  using namespace sdo_abort;
  CHECK(sdo_abort_name(kTimeout) == "SDO protocol timed out");
  CHECK(sdo_abort_name(kUnknownCommand) == "client/server command specifier not valid or unknown");
  CHECK(sdo_abort_name(kInvalidSequence) == "invalid sequence number");
  CHECK(sdo_abort_name(kOutOfMemory) == "out of memory");
  CHECK(sdo_abort_name(kUnsupportedAccess) == "unsupported access to an object");
  CHECK(sdo_abort_name(kWriteOnly) == "attempt to read a write only object");
  CHECK(sdo_abort_name(kReadOnly) == "attempt to write a read only object");
  CHECK(sdo_abort_name(kNoObject) == "object does not exist in the object dictionary");
  CHECK(sdo_abort_name(kTypeLength) ==
        "data type does not match, length of service parameter does not match");
  CHECK(sdo_abort_name(kNoSubindex) == "sub-index does not exist");
  CHECK(sdo_abort_name(kOutOfRange) == "invalid value for parameter");
  CHECK(sdo_abort_name(kGeneral) == "general error");
  CHECK(sdo_abort_name(kCannotStore) == "data cannot be transferred or stored to the application");
  CHECK(sdo_abort_name(kDeviceState) ==
        "data cannot be transferred or stored to the application because of the present device "
        "state");
}

TEST_CASE("an abort code survives the error_code round trip and its message names it",
          "[core][sdo]") {
  for (const auto& [code, name] : kExpected) {
    const std::error_code ec = make_sdo_abort_error(code);
    INFO(ec.message());
    CHECK(ec.category() == sdo_abort_category());
    CHECK(sdo_abort_code(ec) == code);
    CHECK(ec.message() == "SDO abort " + hex(code) + ": " + name);
  }
  // Codes with the top bit set still round-trip (value() carries the bit pattern).
  CHECK(sdo_abort_code(make_sdo_abort_error(0xFFFF'FFFF)) == 0xFFFF'FFFFu);
  // Another category's error is not an abort code, even with an equal value.
  CHECK_FALSE(sdo_abort_code(std::error_code(0x0602'0000, std::generic_category())));
  CHECK_FALSE(sdo_abort_code(std::error_code{}));
}

TEST_CASE("codes outside the table are named as unknown", "[core][sdo]") {
  for (const uint32_t code : {0u, 0x0602'0001u, 0x0503'0001u, 0x1234'5678u, 0xFFFF'FFFFu}) {
    INFO(hex(code));
    CHECK_FALSE(sdo_abort_known(code));
    CHECK(sdo_abort_name(code) == "unknown abort code");
    CHECK(make_sdo_abort_error(code).message() ==
          "SDO abort " + hex(code) + ": unknown abort code");
  }
}
