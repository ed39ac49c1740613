// DLL timing of the MN: threshold counters that count every cycle, the default loss-of-PRes
// threshold, one multiplexed cycle (slots, order, the SoC MC flag), WaitSoCPReq (the cycle budget:
// cycle_budget_test.cpp).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdlib>
#include <map>

#include "mn_rig.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;
using namespace ds1928::powerlink::test;

namespace {
void rebuild(Rig& rig) {
  rig.rebuild();
}
uint64_t mn_cycles(const Rig& rig) {
  return rig.bus->managing_node().counters().cycles;
}
}  // namespace

TEST_CASE("8:1 counters count down in cycles that do not poll a multiplexed CN",
          "[powerlink][mn][timing]") {
  Rig rig({1}, 1);
  rig.config.bus.multiplex_cycles = 4;
  rig.config.bus.nodes[0].multiplexed = true;
  rig.config.bus.nodes[0].multiplex_slot = 2;  // polled when cycles % 4 == 1
  rig.config.bus.thresholds.loss_of_pres = 15;
  rebuild(rig);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // Every 3rd poll lost: one loss per 12 cycles. Counted per cycle (+8, then −1 eleven times)
  // the counter never passes 8; counted only in polled cycles (+8, −1, −1) it reaches 15 at the
  // third loss and resets the CN.
  int polls = 0, losses = 0;
  for (int i = 0; i < 240; ++i) {
    const bool polled = mn_cycles(rig) % 4 == 1;
    rig.cns[0]->drop_pres = polled && polls % 3 == 0;
    if (rig.cns[0]->drop_pres) ++losses;
    if (polled) ++polls;
    rig.step();
    CHECK(rig.st(1).loss_of_pres.value <= 8);
  }
  CHECK(losses == 20);
  CHECK(rig.st(1).loss_of_pres.events == 20);
  CHECK(rig.st(1).loss_of_pres.fired == 0);
  CHECK(rig.st(1).boots == 1);
}

TEST_CASE("Default loss-of-PRes threshold rides through 20 ms of silence, not 21",
          "[powerlink][mn][timing]") {
  CHECK(default_loss_of_pres_threshold(1000) == 168);  // 20 losses tolerated
  CHECK(default_loss_of_pres_threshold(200) == 808);   // 100 losses
  CHECK(default_loss_of_pres_threshold(10000) == 48);  // at least 5 in a row
  CHECK(default_loss_of_pres_threshold(50000) == 48);
  Rig rig({1, 2}, 1);
  rig.config.bus.thresholds.loss_of_pres.reset();  // the documented default
  rebuild(rig);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  CHECK(rig.st(1).loss_of_pres_threshold == 168);
  rig.cns[0]->drop_pres = true;
  for (int i = 0; i < 20; ++i) rig.step();  // a 20 ms stall of the CN's host
  CHECK(rig.st(1).boot == CnBootState::kOperational);
  CHECK(rig.st(1).loss_of_pres.fired == 0);
  rig.cns[0]->drop_pres = false;
  for (int i = 0; i < 200; ++i) rig.step();  // the counter drains
  CHECK(rig.st(1).loss_of_pres.value == 0);
  // A CN that is really gone: reset at its 21st lost PRes.
  rig.cns[0]->drop_pres = true;
  int cycles = 0;
  while (rig.st(1).boot == CnBootState::kOperational && cycles < 100) {
    rig.step();
    ++cycles;
  }
  CHECK(cycles == 21);
  CHECK(rig.st(1).last_reset_reason == MnError::kLossOfPresThreshold);
  CHECK(rig.st(2).boot == CnBootState::kOperational);
}

TEST_CASE("Per-CN loss-of-PRes threshold (0x1C09) wins over the common one",
          "[powerlink][mn][timing]") {
  Rig rig({1, 2}, 1);
  rig.config.bus.thresholds.loss_of_pres = 15;
  rig.config.bus.nodes[1].loss_of_pres_threshold = 0;  // node 2: disabled
  rebuild(rig);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  CHECK(rig.st(1).loss_of_pres_threshold == 15);
  CHECK(rig.st(2).loss_of_pres_threshold == 0);
  rig.cns[1]->drop_pres = true;
  for (int i = 0; i < 50; ++i) rig.step();
  CHECK(rig.st(2).boot == CnBootState::kOperational);
  CHECK(rig.st(2).loss_of_pres.events == 50);
}

TEST_CASE("SoC MC toggles when a multiplexed cycle starts, never without multiplexing",
          "[powerlink][mn][timing]") {
  for (const uint32_t mux : {0u, 4u}) {
    Rig rig({1, 2}, 1);
    rig.config.bus.multiplex_cycles = static_cast<uint8_t>(mux);
    rig.config.bus.nodes[1].multiplexed = mux != 0;
    rebuild(rig);
    std::vector<std::pair<uint64_t, bool>> socs;  // MN cycle, MC
    rig.link.on_send = [&](std::span<const uint8_t> f) {
      if (auto soc = parse_soc(f))
        socs.emplace_back(mn_cycles(rig), soc->multiplexed_cycle_completed);
    };
    REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
    for (int i = 0; i < 40; ++i) rig.step();
    REQUIRE(socs.size() > 40);
    for (const auto& [cycle, mc] : socs) {
      INFO("cycle " << cycle << " multiplex " << mux);
      const bool want = mux == 0 ? false : ((cycle / mux) % 2) == 1;
      CHECK(mc == want);
    }
  }
}

TEST_CASE(
    "One multiplexed cycle: each multiplexed CN polled once in its slot, after the continuous",
    "[powerlink][mn][timing][multiplex]") {
  // MultiplCycleCnt 4 (0x1F98/7) for the network: node 1 continuous, node 2 in slot 1, node 3 in
  // slot 3, node 4 multiplexed without a slot (assigned: slot 2, the lowest of the empty ones).
  Rig rig({1, 2, 3, 4}, 1);
  rig.config.bus.multiplex_cycles = 4;
  for (std::size_t i = 1; i < 4; ++i) rig.config.bus.nodes[i].multiplexed = true;
  rig.config.bus.nodes[1].multiplex_slot = 1;
  rig.config.bus.nodes[2].multiplex_slot = 3;
  rebuild(rig);
  CHECK(rig.st(1).multiplex_slot == 0);
  CHECK(rig.st(2).multiplex_slot == 1);
  CHECK(rig.st(3).multiplex_slot == 3);
  CHECK(rig.st(4).multiplex_slot == 2);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // Each multiplexed CN took MultiplCycleCnt = 4, the same for all; the continuous one none.
  for (std::size_t i = 1; i < 4; ++i)
    CHECK(rig.cns[i]->taken[{0x1F98, 7}] == std::vector<uint8_t>{4});
  CHECK(rig.cns[0]->taken.count({0x1F98, 7}) == 0);
  // The PReqs of each cycle in order, with the cycle's position in the multiplexed cycle (from
  // the SoC MC flag: it toggles at the start of each multiplexed cycle).
  std::vector<std::vector<uint8_t>> order;  // per cycle: nodes polled
  std::vector<bool> ms;                     // MS of each PReq, in order
  std::vector<int> position;                // per cycle: 1..4 within the multiplexed cycle
  bool have_mc = false, last_mc = false;
  int pos = 0;
  rig.link.on_send = [&](std::span<const uint8_t> f) {
    if (auto soc = parse_soc(f)) {
      if (have_mc && soc->multiplexed_cycle_completed != last_mc) pos = 0;
      have_mc = true;
      last_mc = soc->multiplexed_cycle_completed;
      ++pos;
      order.emplace_back();
      position.push_back(pos);
    } else if (auto preq = parse_preq(f)) {
      if (!order.empty()) order.back().push_back(f[15]);
      ms.push_back(preq->multiplexed_slot);
    }
  };
  constexpr int kCycles = 400;
  for (int i = 0; i < kCycles; ++i) rig.step();
  REQUIRE(order.size() == kCycles);
  // From the first MC toggle on, positions run 1..4 and each multiplexed CN is polled exactly in
  // its slot, once per 4 cycles, after node 1, which is polled every cycle.
  std::map<uint8_t, int> polls;
  int checked = 0;
  for (std::size_t c = 0; c < order.size(); ++c) {
    if (c < 8) continue;  // the first multiplexed cycle's start is found by the first toggle
    INFO("cycle " << c << " position " << position[c]);
    REQUIRE(position[c] >= 1);
    REQUIRE(position[c] <= 4);
    std::vector<uint8_t> want{1};
    if (position[c] == 1) want.push_back(2);
    if (position[c] == 2) want.push_back(4);
    if (position[c] == 3) want.push_back(3);
    CHECK(order[c] == want);
    for (uint8_t n : order[c]) ++polls[n];
    ++checked;
  }
  CHECK(polls[1] == checked);
  for (uint8_t n : {2, 3, 4}) CHECK(std::abs(polls[n] * 4 - checked) <= 4);
  // MS set in exactly the multiplexed CNs' PReqs: one in every cycle but position 4.
  CHECK(std::count(ms.begin(), ms.end(), true) > 0);
  for (uint8_t n : {1, 2, 3, 4}) CHECK(rig.st(n).loss_of_pres.events == 0);
}

TEST_CASE("WaitSoCPReq delays the first PReq after the SoC", "[powerlink][mn][timing]") {
  Rig rig({1}, 1);
  rig.config.bus.wait_soc_preq_us = 30;
  rebuild(rig);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // The in-memory link returns at once when nothing is queued; the wait shows as the deadline
  // the MN waits until between the SoC and the PReq: the SoC instant + 30 µs.
  int64_t soc_at = -1;
  bool preq_sent = false;
  std::vector<int64_t> waits;  // between SoC and PReq
  rig.link.on_send = [&](std::span<const uint8_t> f) {
    if (parse_soc(f)) soc_at = g_clock_ns;
    if (parse_preq(f)) preq_sent = true;
  };
  rig.link.on_idle_wait = [&](int64_t deadline) {
    if (soc_at >= 0 && !preq_sent) waits.push_back(deadline);
  };
  g_clock_step_ns = 1000;  // every clock read: 1 µs
  rig.step();
  g_clock_step_ns = 0;
  REQUIRE(soc_at >= 0);
  REQUIRE(preq_sent);
  CHECK(std::find(waits.begin(), waits.end(), soc_at + 30'000) != waits.end());
}
