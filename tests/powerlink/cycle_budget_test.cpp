// The POWERLINK cycle budget (powerlink/cycle_budget.hpp): nominal and worst-case figures computed
// by hand from seed 001's wire times (12.5 bytes/µs; a frame padded to 60 bytes, + FCS 4,
// preamble 8 and inter-frame gap 12: a minimum frame 6.72 µs, an ASnd of AsyncMTU 300 bytes
// (314 with its Ethernet header) 27.04 µs, a 1514-byte frame 123.04 µs).
#include "powerlink/cycle_budget.hpp"

#include <catch2/catch.hpp>
#include <cstdint>
#include <map>
#include <vector>

namespace {

using namespace ds1928::powerlink;

// `count` CNs with minimum frames, each with `timeout` and `latency` µs.
std::vector<BudgetNode> cns(unsigned count, uint32_t timeout, uint32_t latency = 2) {
  std::vector<BudgetNode> v;
  for (unsigned i = 1; i <= count; ++i)
    v.push_back({static_cast<uint8_t>(i), 0, 0, timeout, 0, false, latency});
  return v;
}

double nominal(const std::vector<BudgetNode>& n, const BudgetNetwork& net = {}) {
  return cycle_budget(n, net, BudgetCase::kNominal).total_us();
}
double worst(const std::vector<BudgetNode>& n, const BudgetNetwork& net = {}) {
  return cycle_budget(n, net, BudgetCase::kWorst).total_us();
}

}  // namespace

TEST_CASE("Cycle budget: wire times of seed 001", "[powerlink][budget]") {
  CHECK(wire_time_us(60) == Approx(6.72));
  CHECK(wire_time_us(20) == Approx(6.72));
  CHECK(wire_time_us(async_frame_length(300)) == Approx(27.04));
  CHECK(wire_time_us(async_frame_length(1500)) == Approx(123.04));
}

TEST_CASE("Cycle budget: each term of the nominal and worst-case figure", "[powerlink][budget]") {
  const std::vector<BudgetNode> one{{1, 9, 23, 200, 0, false, 5}};
  BudgetNetwork net;
  net.wait_soc_preq_us = 3;
  const CycleBudget n = cycle_budget(one, net, BudgetCase::kNominal);
  CHECK(n.which == BudgetCase::kNominal);
  CHECK(n.soc_us == Approx(6.72));
  CHECK(n.wait_soc_preq_us == Approx(3));
  CHECK(n.prc_us == 0);
  CHECK(n.isochronous_us == Approx(6.72 + 5 + 6.72));  // PReq, latency, PRes
  CHECK(n.polled_in_worst_cycle == 1);
  CHECK(n.soa_us == Approx(6.72));
  CHECK(n.async_wait_us == Approx(5));  // the invited CN answers as fast as to a PReq
  CHECK(n.asnd_us == Approx(27.04));
  CHECK(n.total_us() == Approx(6.72 + 3 + 18.44 + 6.72 + 5 + 27.04));
  const CycleBudget w = cycle_budget(one, net, BudgetCase::kWorst);
  CHECK(w.isochronous_us == Approx(6.72 + 200 + 6.72));
  CHECK(w.async_wait_us == Approx(100));  // AsyncSlotTimeout
  CHECK(w.asnd_us == Approx(27.04));
  CHECK(w.total_us() == Approx(6.72 + 3 + 213.44 + 6.72 + 100 + 27.04));
  // AsyncMTU bounds the ASnd: at 1500 bytes the frame is 1514.
  net.async_mtu = 1500;
  CHECK(cycle_budget(one, net, BudgetCase::kNominal).asnd_us == Approx(123.04));
  // A latency above the timeout costs the timeout: the MN waits no longer.
  const std::vector<BudgetNode> slow{{1, 0, 0, 50, 0, false, 80}};
  CHECK(cycle_budget(slow, {}, BudgetCase::kNominal).isochronous_us == Approx(6.72 + 50 + 6.72));
}

TEST_CASE("Cycle budget: the field review's networks, nominal accepted, worst case over",
          "[powerlink][budget]") {
  // Four CNs at the default 200 µs timeout, 1 ms: the old worst case was 1090.2 µs (a 1514-byte
  // ASnd). Nominal 6.72 + 4 × (6.72 + 2 + 6.72) + 6.72 + 2 + 27.04 = 104.24; worst case
  // 6.72 + 4 × 213.44 + 6.72 + 100 + 27.04 = 994.24: both fit 1000.
  CHECK(nominal(cns(4, 200)) == Approx(104.24));
  CHECK(worst(cns(4, 200)) == Approx(994.24));
  // Eight CNs at 100 µs, 1 ms (old: 1144.0): nominal 6.72 + 8 × 15.44 + 35.76 = 166.0 fits;
  // worst case 6.72 + 8 × 113.44 + 133.76 = 1048.0 does not: a warning.
  CHECK(nominal(cns(8, 100)) == Approx(166.0));
  CHECK(worst(cns(8, 100)) == Approx(1048.0));
  CHECK(worst(cns(8, 100)) > 1000);
  // Four CNs at 50 µs, 200 µs period (old: 490.2, of which the async phase 229.8): nominal
  // 104.24 fits; worst case 6.72 + 4 × 63.44 + 133.76 = 394.24 does not.
  CHECK(nominal(cns(4, 50)) == Approx(104.24));
  CHECK(worst(cns(4, 50)) == Approx(394.24));
  CHECK(cycle_budget(cns(4, 50), {}, BudgetCase::kWorst).async_us() == Approx(133.76));
}

TEST_CASE("Cycle budget: 8 CNs at 1 ms with a declared latency of 20 us fit, 16 at 50 us do not",
          "[powerlink][budget]") {
  // 6.72 + 8 × (6.72 + 20 + 6.72) + (6.72 + 20 + 27.04) = 328.0 µs nominal; the worst case
  // with the default 200 µs timeout 6.72 + 8 × 213.44 + 133.76 = 1848.0 µs.
  CHECK(nominal(cns(8, 200, 20)) == Approx(328.0));
  CHECK(nominal(cns(8, 200, 20)) <= 1000);
  CHECK(worst(cns(8, 200, 20)) == Approx(1848.0));
  // 16 CNs answering in 50 µs: 6.72 + 16 × 63.44 + (6.72 + 50 + 27.04) = 1105.52 > 1000.
  CHECK(nominal(cns(16, 200, 50)) == Approx(1105.52));
  CHECK(nominal(cns(16, 200, 50)) > 1000);
}

TEST_CASE("Cycle budget: the PRC slot counts the latency (nominal) or the timeout (worst)",
          "[powerlink][budget][prc]") {
  std::vector<BudgetNode> chained = cns(2, 200, 3);
  for (auto& n : chained) n.prc = true;
  // PResMN 6.72 + 2 × (PRes 6.72 + gap 0.96) + 3 = 25.08; worst 6.72 + 15.36 + 200 = 222.08.
  const CycleBudget n = cycle_budget(chained, {}, BudgetCase::kNominal);
  CHECK(n.prc_nodes == 2);
  CHECK(n.prc_us == Approx(25.08));
  CHECK(n.polled_in_worst_cycle == 0);
  CHECK(n.isochronous_us == 0);
  CHECK(cycle_budget(chained, {}, BudgetCase::kWorst).prc_us == Approx(222.08));
}

TEST_CASE("Cycle budget: the multiplexed CNs count in their slots' cycles",
          "[powerlink][budget][multiplex]") {
  std::vector<MultiplexNode> mux{{5, 0}, {2, 3}, {9, 0}, {7, 0}};
  assign_multiplex_slots(mux, 3);
  // Node 2 holds slot 3; 5, 7, 9 in node order take the least loaded, lowest first: 1, 2, 1.
  std::map<uint8_t, uint8_t> slot;
  for (const auto& m : mux) slot[m.node_id] = m.slot;
  CHECK(slot[2] == 3);
  CHECK(slot[5] == 1);
  CHECK(slot[7] == 2);
  CHECK(slot[9] == 1);
  // 1 continuous + nodes 2..9 over 4 slots: the fullest cycle polls three.
  std::vector<BudgetNode> nodes{{1, 9, 23, 100, 0}};
  for (uint8_t n = 2; n <= 9; ++n)
    nodes.push_back({n, 9, 23, 100, static_cast<uint8_t>((n - 2) % 4 + 1)});
  BudgetNetwork net;
  net.wait_soc_preq_us = 10;
  net.multiplex_cycles = 4;
  const CycleBudget w = cycle_budget(nodes, net, BudgetCase::kWorst);
  CHECK(w.polled_in_worst_cycle == 3);
  CHECK(w.isochronous_us == Approx(3 * (100 + 2 * 6.72)));
  CHECK(w.wait_soc_preq_us == 10);
  const CycleBudget n = cycle_budget(nodes, net, BudgetCase::kNominal);
  CHECK(n.polled_in_worst_cycle == 3);
  CHECK(n.isochronous_us == Approx(3 * (2 + 2 * 6.72)));
}
