// DLL timing of the MN: threshold counters that count every cycle, the default loss-of-PRes
// threshold, the SoC MC flag of multiplexed cycles, WaitSoCPReq, the cycle budget.
#include <catch2/catch.hpp>

#include "mn_rig.hpp"
#include "powerlink/cycle_budget.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;
using namespace ds1928::powerlink::test;

namespace {
void rebuild(Rig& rig) {
  rig.bus = std::make_unique<PowerlinkBus>(rig.config, rig.link);
  rig.bus->set_clock(&fake_clock);
  REQUIRE_FALSE(rig.bus->start());
}
uint64_t mn_cycles(const Rig& rig) {
  return rig.bus->managing_node().counters().cycles;
}
}  // namespace

TEST_CASE("8:1 counters count down in cycles that do not poll a multiplexed CN",
          "[powerlink][mn][timing]") {
  Rig rig({1}, 1);
  rig.config.bus.nodes[0].multiplex = 4;  // polled when cycles % 4 == 1
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

TEST_CASE("SoC MC toggles when a multiplexed cycle ends, never without multiplexing",
          "[powerlink][mn][timing]") {
  for (const uint32_t mux : {0u, 4u}) {
    Rig rig({1, 2}, 1);
    rig.config.bus.nodes[1].multiplex = mux;
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

TEST_CASE("Cycle budget: worst cycle on the wire against the period", "[powerlink][timing]") {
  // Seed 001: a 60-byte frame takes 6.72 µs with preamble and inter-frame gap.
  CHECK(wire_time_us(60) == Approx(6.72));
  CHECK(wire_time_us(20) == Approx(6.72));
  CHECK(wire_time_us(1514) == Approx(123.04));
  std::vector<BudgetNode> nodes{{1, 9, 23, 200, 0}};
  const CycleBudget one = cycle_budget(nodes, 0, 100);
  // SoC 6.72 + (PReq 6.72 + 200 + PRes 6.72) + SoA 6.72 + 100 + 123.04
  CHECK(one.total_us() == Approx(449.92));
  CHECK(one.polled_in_worst_cycle == 1);
  // Multiplexed CNs count in the cycles that poll them: 1 continuous + nodes 2..9 over 4 slots.
  nodes.clear();
  nodes.push_back({1, 9, 23, 100, 0});
  for (uint8_t n = 2; n <= 9; ++n) nodes.push_back({n, 9, 23, 100, 4});
  const CycleBudget mux = cycle_budget(nodes, 10, 100);
  CHECK(mux.polled_in_worst_cycle == 3);  // node 1 + two of the eight
  CHECK(mux.isochronous_us == Approx(3 * (100 + 2 * 6.72)));
  CHECK(mux.wait_soc_preq_us == 10);
}
