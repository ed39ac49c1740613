// The measured cycle occupancy's histogram (powerlink/cycle_occupancy.hpp): bins of period/1024,
// quantiles as the upper edge of their bin, never above the exact maximum; beyond the period the
// maximum itself.
#include "powerlink/cycle_occupancy.hpp"

#include <catch2/catch.hpp>

using ds1928::powerlink::OccupancyHistogram;

TEST_CASE("Cycle occupancy: p50, p99 and max of the phases' ends", "[powerlink][budget]") {
  OccupancyHistogram h(1'024'000);  // 1.024 ms: bins of 1 µs
  CHECK(h.bin_ns() == 1000);
  CHECK(h.summary().count == 0);
  CHECK(h.summary().p99_ns == 0);
  // 98 samples at 100.5 µs, one at 300.2 µs, one at 2 ms (past the period).
  for (int i = 0; i < 98; ++i) h.record(100'500);
  h.record(300'200);
  h.record(2'000'000);
  const auto s = h.summary();
  CHECK(s.count == 100);
  CHECK(s.p50_ns == 101'000);  // the upper edge of the bin 100..101 µs
  CHECK(s.p99_ns == 301'000);  // the 99th of 100 samples
  CHECK(s.max_ns == 2'000'000);
  h.record(2'500'000);  // now the 99th percentile falls in the overflow bin: the maximum
  CHECK(h.summary().p99_ns == 2'500'000);
  // Short periods keep 250 ns bins; a negative duration counts as 0.
  OccupancyHistogram small(100'000);
  CHECK(small.bin_ns() == 250);
  small.record(-5);
  CHECK(small.summary().p50_ns == 0);
}
