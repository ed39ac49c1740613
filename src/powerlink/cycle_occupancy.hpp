// How much of each POWERLINK cycle the wire takes, measured: the end of the isochronous phase
// (the last PRes received, or the last PRes timeout) and the end of the asynchronous phase (the
// exchange's end), each after the SoC left. The cycle thread records the stamps it reads anyway
// (no further clock read, no allocation, no lock); any thread reads p50/p99/max.
//
// Bins of period/1024 (at least 250 ns) from 0 to the period, an overflow bin and the exact
// maximum. Writer discipline as in core/cycle_stats.hpp: one writing thread, relaxed atomics
// updated by load+store; a reader sees each word torn-free.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

namespace ds1928::powerlink {

struct OccupancySummary {
  uint64_t count = 0;
  int64_t p50_ns = 0;  // upper edge of the bin holding the quantile, at most the maximum
  int64_t p99_ns = 0;
  int64_t max_ns = 0;
};

class OccupancyHistogram {
 public:
  static constexpr std::size_t kBins = 1024;

  explicit OccupancyHistogram(int64_t period_ns = 1'000'000) noexcept
      : bin_ns_(std::max<int64_t>(250, (period_ns + kBins - 1) / static_cast<int64_t>(kBins))) {}
  OccupancyHistogram(const OccupancyHistogram&) = delete;
  OccupancyHistogram& operator=(const OccupancyHistogram&) = delete;

  // Writer side. Negative durations (a clock racing by a few ns) count as 0.
  void record(int64_t ns) noexcept {
    if (ns < 0) ns = 0;
    const auto i = static_cast<std::size_t>(std::min<int64_t>(ns / bin_ns_, kBins));
    bump(bins_[i]);
    bump(count_);
    if (ns > max_.load(std::memory_order_relaxed)) max_.store(ns, std::memory_order_relaxed);
  }

  // Reader side.
  [[nodiscard]] OccupancySummary summary() const noexcept {
    OccupancySummary s;
    s.count = count_.load(std::memory_order_relaxed);
    s.max_ns = max_.load(std::memory_order_relaxed);
    s.p50_ns = quantile(s.count, 0.50, s.max_ns);
    s.p99_ns = quantile(s.count, 0.99, s.max_ns);
    return s;
  }
  [[nodiscard]] int64_t bin_ns() const noexcept { return bin_ns_; }

 private:
  static void bump(std::atomic<uint64_t>& a) noexcept {
    a.store(a.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  [[nodiscard]] int64_t quantile(uint64_t count, double q, int64_t max_ns) const noexcept {
    if (count == 0) return 0;
    const auto rank = static_cast<uint64_t>(q * static_cast<double>(count) + 0.999999);
    uint64_t seen = 0;
    for (std::size_t i = 0; i < kBins; ++i) {
      seen += bins_[i].load(std::memory_order_relaxed);
      if (seen >= rank) return std::min(static_cast<int64_t>(i + 1) * bin_ns_, max_ns);
    }
    return max_ns;  // in the overflow bin
  }

  int64_t bin_ns_;
  std::array<std::atomic<uint64_t>, kBins + 1> bins_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<int64_t> max_{0};
};

}  // namespace ds1928::powerlink
