// One multiplexed cycle (EPSG DS 301) between the Managing Node (PowerlinkBus) and simulated CNs
// (sim::PowerlinkCn) in one process, on simulated time: MultiplCycleCnt written to every
// multiplexed CN, each polled exactly once per multiplexed cycle in its slot after the continuous
// CNs, MC toggling at the multiplexed cycle's start; the CN's own check of its slot.
#include <catch2/catch.hpp>

#include "pl_sim_rig.hpp"

using namespace pl_sim_rig;

namespace {

// The cycle's place in the multiplexed cycle from the SoCs' MC (1 = the first; 0 before the
// first toggle).
std::vector<int> positions(const std::vector<bool>& mc) {
  std::vector<int> pos;
  int p = 0;
  for (std::size_t i = 0; i < mc.size(); ++i) {
    if (i > 0 && mc[i] != mc[i - 1])
      p = 1;
    else if (p > 0)
      ++p;
    pos.push_back(p);
  }
  return pos;
}

}  // namespace

TEST_CASE("Two multiplexed CNs with MultiplCycleCnt 4 in slots 1 and 3, beside a continuous one",
          "[powerlink][multiplex]") {
  Setup s({{1, false, true}, {2, false, true, true, 1}, {3, false, true, true, 3}}, 4);
  REQUIRE(s.run_until_operational(4000));
  CHECK(s.node(1).multiplex_slot == 0);
  CHECK(s.node(2).multiplex_slot == 1);
  CHECK(s.node(3).multiplex_slot == 3);
  // The same MultiplCycleCnt in both multiplexed CNs (0x1F98/7), none in the continuous one.
  CHECK(s.cns[0]->communication_objects().multiplexed_cycle_count() == 0);
  CHECK(s.cns[1]->communication_objects().multiplexed_cycle_count() == 4);
  CHECK(s.cns[2]->communication_objects().multiplexed_cycle_count() == 4);
  const std::size_t soc0 = s.wire.soc_mc.size();
  const std::size_t preq0 = s.wire.preqs.size();
  const uint64_t loss2 = s.cns[1]->stats().loss_of_preq, loss3 = s.cns[2]->stats().loss_of_preq;
  constexpr int kCycles = 400;
  for (int i = 0; i < kCycles; ++i) REQUIRE(s.step().bus_up);
  const std::vector<int> pos = positions(s.wire.soc_mc);
  // Per cycle of the hold: the nodes polled, in order.
  std::map<uint64_t, std::vector<uint8_t>> polled;
  for (std::size_t i = preq0; i < s.wire.preqs.size(); ++i)
    polled[s.wire.preqs[i].soc - 1].push_back(s.wire.preqs[i].node);
  int cycles = 0, in_slot = 0;
  std::map<uint8_t, int> polls;
  for (std::size_t c = soc0; c < s.wire.soc_mc.size(); ++c) {
    INFO("cycle " << c << " position " << pos[c]);
    REQUIRE(pos[c] >= 1);  // MC toggled before: the cycle's place is known
    REQUIRE(pos[c] <= 4);
    std::vector<uint8_t> want{1};  // the continuous CN first
    if (pos[c] == 1) want.push_back(2);
    if (pos[c] == 3) want.push_back(3);
    CHECK(polled[c] == want);
    in_slot += polled[c] == want;
    for (uint8_t n : polled[c]) ++polls[n];
    ++cycles;
  }
  CHECK(cycles == kCycles);
  CHECK(in_slot == kCycles);
  CHECK(polls[1] == kCycles);
  CHECK(polls[2] == kCycles / 4);
  CHECK(polls[3] == kCycles / 4);
  // The CNs' own view: no PReq missed, none outside its slot.
  CHECK(s.cns[1]->stats().loss_of_preq == loss2);
  CHECK(s.cns[2]->stats().loss_of_preq == loss3);
  CHECK(s.cns[1]->stats().preq_out_of_slot == 0);
  CHECK(s.cns[2]->stats().preq_out_of_slot == 0);
  for (uint8_t n : {1, 2, 3}) CHECK(s.node(n).resets == 0);
}

TEST_CASE("An unassigned multiplexed CN gets the least loaded slot, reported in status",
          "[powerlink][multiplex]") {
  Setup s({{1, false, true, true, 1}, {2, false, true, true, 0}, {3, false, true, true, 0}}, 3);
  CHECK(s.node(1).multiplex_slot == 1);
  CHECK(s.node(2).multiplex_slot == 2);
  CHECK(s.node(3).multiplex_slot == 3);
  REQUIRE(s.run_until_operational(4000));
  for (int i = 0; i < 90; ++i) REQUIRE(s.step().bus_up);
  for (uint8_t n : {1, 2, 3}) CHECK(s.cns[n - 1]->stats().preq_out_of_slot == 0);
}

TEST_CASE("A simulated CN polled outside its slot reports loss of PReq", "[powerlink][multiplex]") {
  // Node 3 is told MultiplCycleCnt 4 (an object written to it) but the MN polls it every cycle:
  // the CN takes its slot from its first PReq once READY_TO_OPERATE and counts every PReq in
  // another cycle of the multiplexed cycle (MC from node 2's multiplexing) as loss of PReq.
  Setup s({{1, false, true}, {2, false, true, true, 1}, {3, false, true, false, 0, 4}}, 4);
  REQUIRE(s.run_until_operational(4000));
  REQUIRE(s.cns[2]->communication_objects().multiplexed_cycle_count() == 4);
  const uint64_t out = s.cns[2]->stats().preq_out_of_slot;
  const uint64_t loss = s.cns[2]->stats().loss_of_preq;
  for (int i = 0; i < 100; ++i) (void)s.step();
  // Three of every four PReqs are outside the slot.
  CHECK(s.cns[2]->stats().preq_out_of_slot - out >= 70);
  CHECK(s.cns[2]->stats().loss_of_preq - loss >= 70);
  // The others are untouched.
  CHECK(s.cns[1]->stats().preq_out_of_slot == 0);
  CHECK(s.cns[0]->stats().preq_out_of_slot == 0);
}
