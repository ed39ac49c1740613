// The simulated CN's NetTime anchor (sim/nettime_anchor.hpp): late SoC arrivals must not move the
// module's NetTime, real changes of the MN's time base must.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdint>
#include <random>

#include "sim/nettime_anchor.hpp"

using ds1928::sim::NetTimeAnchor;

namespace {
constexpr int64_t kBase = 5'000'000'000;  // arrival − RelativeTime of a SoC delivered at once
}

TEST_CASE("NetTime anchor: the first SoC sets it, an earlier arrival lowers it at once", "[sim]") {
  NetTimeAnchor a;
  CHECK_FALSE(a.offset().has_value());
  a.sample(kBase + 300'000);  // the first SoC came 300 µs late
  REQUIRE(a.offset() == kBase + 300'000);
  a.sample(kBase);
  CHECK(a.offset() == kBase);
}

TEST_CASE("NetTime anchor: late SoCs move it by at most 1 µs each", "[sim]") {
  NetTimeAnchor a;
  a.sample(kBase);
  // 50 SoCs each 12 ms late (a stalled thread): the anchor creeps 1 µs per SoC, no more.
  for (int i = 1; i <= 50; ++i) {
    a.sample(kBase + 12'000'000);
    REQUIRE(a.offset() == kBase + i * NetTimeAnchor::kCreepNs);
  }
  // A SoC on time again takes it back down.
  a.sample(kBase);
  CHECK(a.offset() == kBase);
  // Creeping never passes the sample itself.
  a.sample(kBase + 400);
  CHECK(a.offset() == kBase + 400);
}

TEST_CASE("NetTime anchor: a jump of 100 ms or more is taken at once, one just below is not",
          "[sim]") {
  NetTimeAnchor a;
  a.sample(kBase);
  a.sample(kBase + NetTimeAnchor::kJumpNs - 1);
  CHECK(a.offset() == kBase + NetTimeAnchor::kCreepNs);
  a.sample(kBase + NetTimeAnchor::kCreepNs + NetTimeAnchor::kJumpNs);
  CHECK(a.offset() == kBase + NetTimeAnchor::kCreepNs + NetTimeAnchor::kJumpNs);
}

TEST_CASE("NetTime anchor: random delivery delays leave it within the smallest delay", "[sim]") {
  std::mt19937_64 rng(18);
  std::uniform_int_distribution<int64_t> delay(0, 20'000'000);  // up to 20 ms late
  NetTimeAnchor a;
  int64_t smallest = INT64_MAX;
  for (int i = 0; i < 10000; ++i) {
    const int64_t d = i == 100 ? 0 : delay(rng);  // one SoC delivered at once
    smallest = std::min(smallest, d);
    a.sample(kBase + d);
    REQUIRE(a.offset().has_value());
    // Never below the true base, never above the smallest delay seen plus the creep since.
    REQUIRE(*a.offset() >= kBase);
  }
  CHECK(smallest == 0);
  // After the on-time SoC the anchor rose by creep only: at most 1 µs per later SoC.
  CHECK(*a.offset() <= kBase + 9899 * NetTimeAnchor::kCreepNs);
}
