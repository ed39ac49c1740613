#include "core/cycle_stats.hpp"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

using ds1928::CycleStats;
using ds1928::LatencyHistogram;

namespace {
constexpr int64_t kBin = LatencyHistogram::kBinWidthNs;

// The exact q-quantile of a sample set by the same rank rule the histogram uses.
int64_t exact_quantile(std::vector<int64_t> v, double q) {
  std::sort(v.begin(), v.end());
  auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  rank = std::clamp<std::size_t>(rank, 1, v.size());
  return v[rank - 1];
}
}  // namespace

TEST_CASE("histogram quantiles of a hand-filled distribution", "[cycle_stats]") {
  auto h = std::make_unique<LatencyHistogram>();
  // 900 × 1.0 µs, 90 × 5.1 µs, 9 × 20.0 µs, 1 × 3 ms.
  for (int i = 0; i < 900; ++i) h->record(1000);
  for (int i = 0; i < 90; ++i) h->record(5100);
  for (int i = 0; i < 9; ++i) h->record(20000);
  h->record(3'000'000);

  const auto s = h->summary();
  CHECK(s.count == 1000);
  CHECK(s.overflow == 0);
  CHECK(s.min_ns == 1000);
  CHECK(s.max_ns == 3'000'000);
  CHECK(s.mean_ns == (900 * 1000 + 90 * 5100 + 9 * 20000 + 3'000'000) / 1000);
  // Upper edges of the bins [1000,1250), [5000,5250), [20000,20250).
  CHECK(s.p50_ns == 1250);
  CHECK(s.p99_ns == 5250);
  CHECK(s.p999_ns == 20250);
  CHECK(h->quantile(1.0) == 3'000'000);
  CHECK(h->bin(1000 / kBin) == 900);
  CHECK(h->bin(5100 / kBin) == 90);
}

TEST_CASE("histogram quantile is clamped to the exact maximum", "[cycle_stats]") {
  auto h = std::make_unique<LatencyHistogram>();
  h->record(12'345);
  h->record(12'345);
  const auto s = h->summary();
  CHECK(s.p50_ns == 12'345);  // bin edge 12 500 would overstate a known maximum
  CHECK(s.p999_ns == 12'345);
  CHECK(s.max_ns == 12'345);
}

TEST_CASE("histogram overflow and negative samples", "[cycle_stats]") {
  auto h = std::make_unique<LatencyHistogram>();
  for (int i = 0; i < 98; ++i) h->record(-40);  // a clock read a hair before the deadline
  h->record(LatencyHistogram::kRangeNs);        // first value past the fine range
  h->record(25'000'000);
  const auto s = h->summary();
  CHECK(s.count == 100);
  CHECK(s.overflow == 2);
  CHECK(h->bin(0) == 98);
  CHECK(s.min_ns == 0);
  CHECK(s.p50_ns == kBin);
  CHECK(s.p99_ns == 25'000'000);  // in the overflow bin: the exact max is all that is known
  CHECK(s.max_ns == 25'000'000);
}

TEST_CASE("empty histogram reports zeros", "[cycle_stats]") {
  auto h = std::make_unique<LatencyHistogram>();
  const auto s = h->summary();
  CHECK(s.count == 0);
  CHECK(s.p99_ns == 0);
  CHECK(s.max_ns == 0);
  CHECK(h->quantile(0.5) == 0);
}

TEST_CASE("histogram quantiles match the exact quantiles within one bin", "[cycle_stats]") {
  std::mt19937_64 rng(1928);
  std::lognormal_distribution<double> latency(std::log(15000.0), 0.6);  // ~15 µs, long tail
  std::vector<int64_t> samples;
  auto h = std::make_unique<LatencyHistogram>();
  for (int i = 0; i < 200000; ++i) {
    const auto v = static_cast<int64_t>(latency(rng));
    samples.push_back(v);
    h->record(v);
  }
  for (double q : {0.5, 0.9, 0.99, 0.999}) {
    const int64_t exact = exact_quantile(samples, q);
    const int64_t got = h->quantile(q);
    INFO("q=" << q << " exact=" << exact << " histogram=" << got);
    if (exact < LatencyHistogram::kRangeNs) {
      CHECK(got > exact);  // upper bin edge: never understates
      CHECK(got <= exact + kBin);
    }
  }
  CHECK(h->summary().max_ns == *std::max_element(samples.begin(), samples.end()));
}

TEST_CASE("stats reset is applied by the writer only when requested", "[cycle_stats]") {
  auto stats = std::make_unique<CycleStats>();
  for (int i = 0; i < 10; ++i) stats->record_cycle(2000, 7000);
  stats->record_overrun(3);
  stats->apply_pending_reset();  // nothing requested: no effect
  auto s = stats->snapshot();
  CHECK(s.cycles == 10);
  CHECK(s.overruns == 1);
  CHECK(s.skipped_cycles == 3);
  CHECK(s.wake_latency.count == 10);
  CHECK(s.work.p50_ns == 7000);
  CHECK(s.reset_generation == 0);

  stats->request_reset();
  s = stats->snapshot();
  CHECK(s.cycles == 10);  // a request alone changes nothing: the writer applies it
  stats->apply_pending_reset();
  s = stats->snapshot();
  CHECK(s.reset_generation == 1);
  CHECK(s.cycles == 0);
  CHECK(s.overruns == 0);
  CHECK(s.skipped_cycles == 0);
  CHECK(s.wake_latency.count == 0);
  CHECK(s.work.max_ns == 0);
  CHECK(stats->wake_latency().bin(2000 / kBin) == 0);

  stats->record_cycle(500, 900);
  s = stats->snapshot();
  CHECK(s.cycles == 1);
  CHECK(s.wake_latency.min_ns == 500);
  CHECK(s.wake_latency.max_ns == 500);
  // Quantiles count only what came after the reset (the ten 7000 ns samples are gone).
  CHECK(s.work.p50_ns == 900);
  CHECK(s.work.p999_ns == 900);
  CHECK(s.work.count == 1);
}

TEST_CASE("stats reset leaves the bins to the requester: the writer restarts scalars only",
          "[cycle_stats]") {
  auto stats = std::make_unique<CycleStats>();
  for (int i = 0; i < 100; ++i) stats->record_cycle(1000 + 250 * i, 5000);
  stats->record_cycle(LatencyHistogram::kRangeNs + 1, 5000);  // one in the overflow bin
  REQUIRE(stats->wake_latency().overflow() == 1);
  stats->request_reset();
  // The histogram restarts at the request (its bins read zero), before the writer applies it.
  for (std::size_t i = 0; i < LatencyHistogram::kBins; ++i)
    REQUIRE(stats->wake_latency().bin(i) == 0);
  CHECK(stats->wake_latency().overflow() == 0);
  CHECK(stats->wake_latency().quantile(0.5) == 0);
  stats->apply_pending_reset();
  // New samples in the very bins that held old ones count from zero.
  stats->record_cycle(1000, 5000);
  stats->record_cycle(1100, 5000);
  CHECK(stats->wake_latency().bin(1000 / kBin) == 2);
  const auto s = stats->snapshot();
  CHECK(s.wake_latency.count == 2);
  CHECK(s.wake_latency.overflow == 0);
  CHECK(s.wake_latency.p50_ns == 1100);  // upper edge 1250, clamped to the maximum
  CHECK(s.wake_latency.max_ns == 1100);
  // A second reset works the same way.
  stats->request_reset();
  stats->apply_pending_reset();
  CHECK(stats->snapshot().wake_latency.count == 0);
  CHECK(stats->wake_latency().bin(1000 / kBin) == 0);
  CHECK(stats->snapshot().reset_generation == 2);
}
