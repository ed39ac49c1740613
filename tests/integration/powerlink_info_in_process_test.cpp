// The additional-information channels over POWERLINK, in one process on simulated time: the MN
// writes EnDatInfoCmd0N by SDO at boot and a TPDO mapping that carries EnDatInfoOK and
// EnDatInfo01/02 (the object scheme's sub-indices 0x30..0x34); the simulated CN's module serves
// the channels from its encoder and the PRes brings them cyclically: the values the MN decodes
// are the encoder's, they follow it when it changes, and a channel the encoder cannot answer
// has its OK bit clear.
#include <catch2/catch.hpp>

#include "core/axis_info.hpp"
#include "endat/names.hpp"
#include "pl_sim_rig.hpp"
#include "powerlink/pdo_image.hpp"
#include "x20ds1928/info_channels.hpp"

using namespace pl_sim_rig;

namespace {

std::vector<uint8_t> u64le(uint64_t v) {
  std::vector<uint8_t> d(8);
  for (int i = 0; i < 8; ++i) d[i] = static_cast<uint8_t>(v >> (8 * i));
  return d;
}

void map(std::vector<ds1928::CnObjectWrite>& w, uint16_t index,
         const std::vector<pl::PdoMapEntry>& entries) {
  w.push_back({index, 0, {0}, false});
  for (std::size_t i = 0; i < entries.size(); ++i)
    w.push_back({index, static_cast<uint8_t>(i + 1), u64le(entries[i].to_u64()), false});
  w.push_back({index, 0, {static_cast<uint8_t>(entries.size())}, false});
}

ds1928::InfoChannelConfig named(const char* name) {
  const ds1928::NamedInfo* n = ds1928::find_named_info(name);
  REQUIRE(n != nullptr);
  return {name, ds1928::named_info_request(*n), n->is_signed};
}

}  // namespace

TEST_CASE("POWERLINK: EnDatInfo01..03 in the mapped PRes equal the simulated encoder's",
          "[powerlink][info]") {
  // The packed block's mapping, then EnDatInfoOK and three words right after it.
  const std::vector<pl::ModuleSpec> specs{{1, 7, 7}};
  auto packed = pl::make_layout(specs);
  REQUIRE(packed);
  auto tpdo = pl::tpdo_mapping_of(*packed, {});
  const auto end = static_cast<uint16_t>(packed->pres_size * 8);
  tpdo.push_back({0x2001, 0x30, end, 8});
  tpdo.push_back({0x2001, 0x31, static_cast<uint16_t>(end + 8), 16});
  tpdo.push_back({0x2001, 0x32, static_cast<uint16_t>(end + 24), 16});
  tpdo.push_back({0x2001, 0x33, static_cast<uint16_t>(end + 40), 16});
  NodeSpec node{1, false, true};
  map(node.writes, pl::obj::kTxPdoMapping, tpdo);
  map(node.writes, pl::obj::kRxPdoMapping, pl::rpdo_mapping_of(*packed, {}));
  node.info = {
      named("temperature1"),
      named("temperature2"),
      // A parameter beyond the encoder's memory area: never OK.
      {"missing", {ds1928::info_command::kReadParameter, 0xA1, 0xF0, std::nullopt}, false}};
  Setup s({node});
  REQUIRE(s.run_until_operational(4000));
  auto& encoder = s.cns[0]->module(0).endat().encoder();
  encoder.set_temperature_c(55.3);
  encoder.set_temperature2_c(-5.0);

  ds1928::AxisInfo info;
  info.configured = 0b0111;
  auto run = [&](int cycles) {
    for (int i = 0; i < cycles; ++i) {
      REQUIRE(s.step().bus_up);
      if (s.io[0].inputs_fresh)
        ds1928::update_axis_info(info, s.io[0].inputs.info_ok, s.io[0].inputs.info, g_now_ns);
    }
  };
  run(50);
  CHECK(s.io[0].inputs.info_ok == 0b0011);
  CHECK(info.valid == 0b0011);
  CHECK(info.value[0] == ds1928::endat::temperature_raw(55.3));
  CHECK(info.value[0] == 3285);
  CHECK(info.value[1] == 2682);
  CHECK(info.read_ns[2] == 0);  // never OK
  CHECK(ds1928::info_age_us(info, 0, g_now_ns) < 2000);
  // The encoder warms up: the next PRes carry it.
  encoder.set_temperature_c(80.0);
  run(20);
  CHECK(info.value[0] == ds1928::endat::temperature_raw(80.0));
  CHECK(info.value[1] == 2682);
}
