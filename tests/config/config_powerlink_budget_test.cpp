// The POWERLINK cycle budget of a configuration: a nominal cycle that does not fit is refused,
// naming each term with its figure; a worst case that does not fit is a warning; AsyncMTU from the
// MN's CDC (0x1F98/8) or the YAML; pres_latency_us. Figures by hand from seed 001's wire times:
// a minimum frame 6.72 µs, an ASnd of AsyncMTU 300 (314 bytes with the Ethernet header) 27.04 µs.
#include <stdlib.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "config/config_loader.hpp"
#include "config/powerlink_budget.hpp"
#include "config_test_util.hpp"
#include "powerlink/concise_dcf.hpp"

namespace {

using namespace ds1928;
using powerlink::CdcEntry;
using test::from;
using test::le;
using test::one_error;

// `count` nodes, each with `extra` keys.
std::string nodes(unsigned count, const std::string& extra) {
  std::string s;
  for (unsigned i = 1; i <= count; ++i)
    s += "    - {node_id: " + std::to_string(i) + (extra.empty() ? "" : ", " + extra) + "}\n";
  return s;
}

std::string network(unsigned period_us, const std::string& node_list) {
  return "bus: powerlink\ncycle: {period_us: " + std::to_string(period_us) +
         "}\npowerlink:\n  interface: eth1\n  nodes:\n" + node_list;
}

}  // namespace

TEST_CASE(
    "Budget: 8 CNs at 1 ms with a declared latency of 20 us are accepted, the worst case warned",
    "[config][powerlink][budget]") {
  const ConfigResult r = from(network(1000, nodes(8, "pres_latency_us: 20")));
  INFO(r.error_report());
  REQUIRE(r.ok());
  CHECK(r.config().powerlink.nodes[7].pres_latency_us == 20);
  // Nominal 6.72 + 8 × (6.72 + 20 + 6.72) + 6.72 + 20 + 27.04 = 328.0 µs; worst case with the
  // default PRes timeout of 200: 6.72 + 8 × 213.44 + 6.72 + 100 + 27.04 = 1848.0 µs.
  const PowerlinkCycleBudget b = powerlink_cycle_budget(r.config());
  CHECK(b.period_us == 1000);
  CHECK(b.nominal.total_us() == Approx(328.0));
  CHECK(b.worst.total_us() == Approx(1848.0));
  CHECK(b.nominal_fits());
  CHECK_FALSE(b.worst_fits());
  const std::string w = worst_case_warning(b, r.config().powerlink.async_mtu);
  CHECK_THAT(w, Catch::Contains("worst case (every CN answering at its PRes timeout) takes "
                                "1848.0 us, 848.0 us more"));
  CHECK_THAT(w, Catch::Contains("8 PReq/PRes with their PRes timeouts 1707.5"));
  CHECK_THAT(w, Catch::Contains("SoA 6.7 + AsyncSlotTimeout 100.0 + ASnd of AsyncMTU 300 bytes "
                                "27.0"));
  // Three CNs with the defaults: 6.72 + 3 × 213.44 + 133.76 = 780.8, the worst case fits.
  const ConfigResult three = from(network(1000, nodes(3, "")));
  REQUIRE(three.ok());
  const PowerlinkCycleBudget b3 = powerlink_cycle_budget(three.config());
  CHECK(b3.worst.total_us() == Approx(780.8));
  CHECK(b3.worst_fits());
  CHECK(worst_case_warning(b3, 300).empty());
}

TEST_CASE("Budget: a nominal cycle that does not fit is refused, naming each term",
          "[config][powerlink][budget]") {
  // Two CNs answering in 20 µs at 100 µs: 6.72 + 2 × 33.44 + (6.72 + 20 + 27.04) = 127.36.
  const std::string e =
      one_error(network(100, nodes(2, "pres_latency_us: 20, pres_timeout_us: 50")));
  CHECK_THAT(e, Catch::Contains("does not fit cycle.period_us 100"));
  CHECK_THAT(e, Catch::Contains("(nominal) it takes 127.4 us on the wire, 27.4 us more"));
  CHECK_THAT(e, Catch::Contains("SoC 6.7, WaitSoCPReq 0.0, PRC slot of 0 node(s) 0.0, 2 PReq/PRes "
                                "with their PRes latencies 66.9, SoA 6.7 + ASnd latency 20.0 + "
                                "ASnd of AsyncMTU 300 bytes 27.0"));
  // Multiplexed over two cycles, one of them per cycle: 6.72 + 33.44 + 53.76 = 93.92 fits.
  const ConfigResult ok =
      from(network(100, nodes(2, "pres_latency_us: 20, pres_timeout_us: 50, multiplexed: true")) +
           "  multiplex_cycles: 2\n");
  INFO(ok.error_report());
  CHECK(ok.errors().empty());
}

TEST_CASE("Budget: PRC nodes share the PRC slot, their longest latency counted once",
          "[config][powerlink][budget][prc]") {
  // Two nodes answering in 40 µs: polled, 6.72 + 2 × 53.44 + (6.72 + 40 + 27.04) = 187.36, over
  // 150; chained, 6.72 + (PResMN 6.72 + 2 × 7.68 + 40) + 73.76 = 142.56, which fits.
  const std::string two = "pres_latency_us: 40, pres_timeout_us: 60";
  CHECK_THAT(one_error(network(150, nodes(2, two))), Catch::Contains("187.4 us on the wire"));
  const ConfigResult ok = from(network(150, nodes(2, two + ", prc: true")));
  INFO(ok.error_report());
  CHECK(ok.errors().empty());
  CHECK(powerlink_cycle_budget(ok.config()).nominal.total_us() == Approx(142.56));
  // Mixed: the message names the PRC slot (6.72 + 7.68 + 40) and the polled node.
  const std::string e = one_error(network(
      100, "    - {node_id: 1, " + two + ", prc: true}\n    - {node_id: 2, " + two + "}\n"));
  CHECK_THAT(e, Catch::Contains("PRC slot of 1 node(s) 54.4"));
  CHECK_THAT(e, Catch::Contains("1 PReq/PRes"));
  // The PResMN grows with the chained node's outputs: three modules of MTU 15 give 51 bytes, a
  // PResMN of 7.92 µs instead of 6.72; its PRes (93 bytes) 11.28 + 0.96: 7.92 + 12.24 + 40.
  const std::string e2 =
      one_error(network(100, "    - {node_id: 1, " + two + ", prc: true}\n    - {node_id: 2, " +
                                 two + "}\n") +
                "axes:\n"
                "  - {name: a, node: 1, slot: 1, module: {input_mtu: 15, "
                "output_mtu: 15}}\n"
                "  - {name: b, node: 1, slot: 2, module: {input_mtu: 15, "
                "output_mtu: 15}}\n"
                "  - {name: c, node: 1, slot: 3, module: {input_mtu: 15, "
                "output_mtu: 15}}\n");
  CHECK_THAT(e2, Catch::Contains("PRC slot of 1 node(s) 60.2"));
}

TEST_CASE("Budget: pres_latency_us below the node's timeout, AsyncMTU in DS 301's range",
          "[config][powerlink][budget]") {
  const std::string e =
      one_error(network(1000, nodes(1, "pres_latency_us: 90, pres_timeout_us: 90")));
  CHECK_THAT(e, Catch::Contains("powerlink.nodes[0].pres_latency_us"));
  CHECK_THAT(e, Catch::Contains("pres_latency_us (90) must be less than the node's pres_timeout_us "
                                "(90)"));
  CHECK_THAT(one_error(network(1000, nodes(1, "")) + "  async_mtu: 299\n"),
             Catch::Contains("powerlink.async_mtu: 299 is out of range 300..1500"));
  // The default is a hardware CN's (2 µs), and AsyncMTU 300; both shown by --print-config.
  const ConfigResult r = from(network(1000, nodes(1, "")) + "  async_mtu: 1500\n");
  REQUIRE(r.ok());
  CHECK(r.config().powerlink.nodes[0].pres_latency_us == 2);
  CHECK(r.config().powerlink.async_mtu == 1500);
  const std::string dumped = dump_config(r.config());
  CHECK_THAT(dumped, Catch::Contains("pres_latency_us: 2\n"));
  CHECK_THAT(dumped, Catch::Contains("async_mtu: 1500\n"));
  // A longer AsyncMTU lengthens the ASnd: 1514 bytes, 123.04 µs.
  CHECK(powerlink_cycle_budget(r.config()).nominal.asnd_us == Approx(123.04));
}

TEST_CASE("Budget: AsyncMTU from the MN's CDC (0x1F98/8) unless the YAML sets it",
          "[config][powerlink][budget][cdc]") {
  char tmpl[] = "/tmp/ds1928-budget-XXXXXX";
  REQUIRE(::mkdtemp(tmpl) != nullptr);
  const std::filesystem::path dir = tmpl;
  const auto with_cdc = [&](const std::vector<CdcEntry>& mn) {
    const auto bytes = powerlink::encode_cdc(mn);
    std::ofstream(dir / "mnobd.cdc", std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  };
  const std::string cfg = (dir / "ds1928d.yaml").string();
  const std::string yaml = network(1000, nodes(1, "")) + "  cdc: mnobd.cdc\n";
  with_cdc({{0x1F98, 8, le(1500, 2)}});
  const ConfigResult r = from(yaml, cfg);
  INFO(r.error_report());
  REQUIRE(r.ok());
  CHECK(r.config().powerlink.async_mtu == 1500);
  CHECK_THAT(dump_config(r.config()),
             Catch::Contains("async_mtu: 1500  # cdc 0x1F98/8 NMT_CycleTiming_REC.AsyncMTU_U16 = "
                             "1500 bytes (byte 4)"));
  const ConfigResult y = from(yaml + "  async_mtu: 600\n", cfg);
  REQUIRE(y.ok());
  CHECK(y.config().powerlink.async_mtu == 600);
  CHECK_THAT(dump_config(y.config()), Catch::Contains("async_mtu: 600  # yaml"));
  // Below DS 301's minimum: refused with the object and its offset in the CDC.
  with_cdc({{0x1F98, 8, le(200, 2)}});
  CHECK_THAT(one_error(yaml, cfg),
             Catch::Contains("powerlink.cdc: 0x1F98/8 NMT_CycleTiming_REC.AsyncMTU_U16 = 200 bytes "
                             "(byte 4) is below DS 301's minimum of 300 bytes"));
  // Without the object: the default, and the dump says so.
  with_cdc({{0x1F81, 1, le(3, 4)}});
  const ConfigResult d = from(yaml, cfg);
  REQUIRE(d.ok());
  CHECK(d.config().powerlink.async_mtu == 300);
  CHECK_THAT(dump_config(d.config()), Catch::Contains("async_mtu: 300  # default"));
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
}
