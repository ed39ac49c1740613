// cycle.timebase: tai — the timeline on whole TAI multiples of the period, driven by a fake
// clock (the machine's clock is never stepped), and the engine on the real CLOCK_TAI.
#include "core/timebase.hpp"

#include <catch2/catch.hpp>
#include <cstdlib>
#include <vector>

#include "core/cycle_engine.hpp"

using namespace ds1928;

namespace {

constexpr int64_t kPeriod = 1'000'000;
constexpr int64_t kTaiOffset = 1'700'000'037'123'457;  // TAI − MONOTONIC of the fake clock

// TAI instant of cycle n of a timeline.
int64_t tai_start(const TaiTimeline& t, int64_t n) {
  return t.t0() + n * kPeriod + t.tai_offset();
}

}  // namespace

TEST_CASE("two timelines anchored at different times start their cycles on the same TAI grid") {
  TaiTimeline a(kPeriod), b(kPeriod);
  a.anchor(5'000'000'123, kTaiOffset);
  b.anchor(5'037'654'321, kTaiOffset);  // started 37.65 ms later
  for (int64_t n : {0, 1, 999}) {
    CHECK(tai_start(a, n) % kPeriod == 0);
    CHECK(tai_start(b, n) % kPeriod == 0);
    CHECK((b.t0() + n * kPeriod - a.t0()) % kPeriod == 0);
  }
  // Cycle 0 is at least one period ahead of the anchor instant, and at most two.
  CHECK(a.t0() - 5'000'000'123 >= kPeriod);
  CHECK(a.t0() - 5'000'000'123 < 2 * kPeriod);
  CHECK(a.steps() == 0);
}

TEST_CASE("a step of the TAI clock re-anchors once, by the step modulo the period") {
  TaiTimeline t(kPeriod);
  t.anchor(1'000'000'000, kTaiOffset);
  const int64_t t0 = t.t0();
  // Measurement noise below the threshold: nothing moves.
  CHECK(t.follow(kTaiOffset + 800) == 0);
  CHECK(t.follow(kTaiOffset - 1'200) == 0);
  CHECK(t.t0() == t0);
  // One disturbed reading is not a step.
  CHECK(t.follow(kTaiOffset + 250'000) == 0);
  CHECK(t.follow(kTaiOffset) == 0);
  CHECK(t.steps() == 0);
  // TAI stepped forward by 37 s + 300 µs: the grid moves by −300 µs, once.
  const int64_t stepped = kTaiOffset + 37'000'300'000;
  CHECK(t.follow(stepped) == 0);  // seen once
  CHECK(t.follow(stepped) == -300'000);
  CHECK(t.steps() == 1);
  CHECK(t.last_step_ns() == -300'000);
  CHECK(t.t0() == t0 - 300'000);
  CHECK(tai_start(t, 5) % kPeriod == 0);
  // The following cycles: no further re-anchor.
  for (int i = 0; i < 100; ++i) CHECK(t.follow(stepped + (i % 3) * 100) == 0);
  CHECK(t.steps() == 1);
  // TAI stepped back by 0.7 periods: the grid's instants move by +0.7 periods, which on the
  // grid is −0.3 periods: the shorter way, never more than half a period.
  const int64_t back = stepped - 700'000;
  CHECK(t.follow(back) == 0);
  CHECK(t.follow(back) == -300'000);
  CHECK(t.steps() == 2);
  CHECK(tai_start(t, 9) % kPeriod == 0);
}

namespace {

struct StartRecorder final : CycleTask {
  std::vector<CycleContext> seen;
  void run_cycle(const CycleContext& ctx) noexcept override {
    if (seen.size() < seen.capacity()) seen.push_back(ctx);
  }
};

CycleConfig tai_config() {
  CycleConfig c;
  c.period_us = 1000;
  c.lock_memory = false;
  c.hold_cpu_dma_latency = false;
  c.timebase = TimebaseKind::Tai;
  return c;
}

}  // namespace

TEST_CASE("engines on the tai timebase: cycle starts on TAI multiples, aligned across engines") {
  StartRecorder first, second;
  first.seen.reserve(20);
  second.seen.reserve(20);
  CycleEngine a(tai_config(), first);
  REQUIRE(a.run_cycles(20));
  CycleEngine b(tai_config(), second);  // started later, at an arbitrary phase
  REQUIRE(b.run_cycles(20));
  REQUIRE(first.seen.size() == 20);
  REQUIRE(second.seen.size() == 20);
  for (const auto* rec : {&first, &second}) {
    for (const CycleContext& ctx : rec->seen) {
      REQUIRE(ctx.timebase != nullptr);
      CHECK(ctx.start_ns == ctx.t0_ns + static_cast<int64_t>(ctx.index) * kPeriod);
      // On the TAI grid, to the measurement of TAI − MONOTONIC (two vDSO readings apart).
      int64_t phase = (ctx.start_ns + ctx.timebase->tai_offset_ns) % kPeriod;
      if (phase > kPeriod / 2) phase -= kPeriod;
      CHECK(std::abs(phase) < TaiTimeline::kStepThresholdNs);
    }
  }
  int64_t apart = (second.seen[0].start_ns - first.seen[0].start_ns) % kPeriod;
  if (apart > kPeriod / 2) apart -= kPeriod;
  CHECK(std::abs(apart) < 2 * TaiTimeline::kStepThresholdNs);
  CHECK(first.seen[0].timebase->kind == TimebaseKind::Tai);
}
