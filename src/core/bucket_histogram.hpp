// A histogram with a handful of fixed bucket bounds, for the OpenMetrics endpoint: PRes
// latency per POWERLINK CN (cycle thread), EnDat command latency per axis (normal thread).
//
// Writer discipline as in cycle_stats.hpp: one writing thread, every word a relaxed atomic
// updated by load+store (no locked read-modify-write on the cycle path, no allocation); any
// thread reads each word torn-free. A reader may see a sample in its bucket before it is in the
// sum, which a scrape every few seconds never notices.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <tuple>
#include <type_traits>

namespace ds1928 {

// `Bounds`: a constant std::array<int64_t, N> of upper bounds in ns (inclusive, ascending).
// Samples above the last bound land in the +Inf bucket.
template <const auto& Bounds>
class BucketHistogram {
 public:
  static constexpr std::size_t N = std::tuple_size_v<std::remove_cvref_t<decltype(Bounds)>>;

  BucketHistogram() noexcept = default;
  BucketHistogram(const BucketHistogram&) = delete;
  BucketHistogram& operator=(const BucketHistogram&) = delete;

  // Writer side. Negative durations (clocks racing by a few ns) count as 0.
  void record(int64_t ns) noexcept {
    if (ns < 0) ns = 0;
    std::size_t i = 0;
    while (i < N && ns > Bounds[i]) ++i;  // N is a dozen: a linear scan is as good as a search
    counts_[i].store(counts_[i].load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    sum_ns_.store(sum_ns_.load(std::memory_order_relaxed) + ns, std::memory_order_relaxed);
  }

  // Reader side.
  [[nodiscard]] static constexpr const auto& upper_ns() noexcept { return Bounds; }
  // Samples in bucket i alone (not cumulative); i == N is the +Inf bucket.
  [[nodiscard]] uint64_t bucket(std::size_t i) const noexcept {
    return counts_[i].load(std::memory_order_relaxed);
  }
  [[nodiscard]] int64_t sum_ns() const noexcept { return sum_ns_.load(std::memory_order_relaxed); }

 private:
  std::array<std::atomic<uint64_t>, N + 1> counts_{};
  std::atomic<int64_t> sum_ns_{0};
};

}  // namespace ds1928
