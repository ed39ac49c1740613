#include "core/cycle_stats.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ds1928 {

namespace {
constexpr int64_t kNoMin = std::numeric_limits<int64_t>::max();
}

void LatencyHistogram::record(int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  if (ns >= kRangeNs) {
    bump(overflow_);
  } else {
    bump(bins_[static_cast<std::size_t>(ns / kBinWidthNs)]);
  }
  bump(count_);
  sum_.store(sum_.load(std::memory_order_relaxed) + ns, std::memory_order_relaxed);
  if (ns < min_.load(std::memory_order_relaxed)) min_.store(ns, std::memory_order_relaxed);
  if (ns > max_.load(std::memory_order_relaxed)) max_.store(ns, std::memory_order_relaxed);
}

LatencyHistogram::LatencyHistogram() noexcept {
  for (auto& b : bins_) b.store(0, std::memory_order_relaxed);
  for (auto& b : base_) b.store(0, std::memory_order_relaxed);
  restart_scalars();
}

void LatencyHistogram::restart_scalars() noexcept {
  count_.store(0, std::memory_order_relaxed);
  sum_.store(0, std::memory_order_relaxed);
  min_.store(kNoMin, std::memory_order_relaxed);
  max_.store(0, std::memory_order_relaxed);
}

void LatencyHistogram::rebase() noexcept {
  for (std::size_t i = 0; i < kBins; ++i)
    base_[i].store(bins_[i].load(std::memory_order_relaxed), std::memory_order_relaxed);
  overflow_base_.store(overflow_.load(std::memory_order_relaxed), std::memory_order_relaxed);
}

int64_t LatencyHistogram::quantile(double q) const noexcept {
  // The total is summed from the bins themselves so that the walk below always reaches the
  // target, even when the writer is between two of its stores.
  uint64_t total = overflow();
  for (std::size_t i = 0; i < kBins; ++i) total += bin(i);
  if (total == 0) return 0;
  q = std::clamp(q, 0.0, 1.0);
  auto target = static_cast<uint64_t>(std::ceil(q * static_cast<double>(total)));
  target = std::clamp<uint64_t>(target, 1, total);
  const int64_t max = max_ns();
  uint64_t seen = 0;
  for (std::size_t i = 0; i < kBins; ++i) {
    seen += bin(i);
    if (seen >= target) {
      return std::min(static_cast<int64_t>(i + 1) * kBinWidthNs, max);
    }
  }
  return max;  // in the overflow bin: only the maximum is known exactly
}

HistogramSummary LatencyHistogram::summary() const noexcept {
  HistogramSummary s;
  s.count = count_.load(std::memory_order_relaxed);
  s.overflow = overflow();
  if (s.count == 0) return s;
  s.min_ns = min_.load(std::memory_order_relaxed);
  if (s.min_ns == kNoMin) s.min_ns = 0;
  s.max_ns = max_ns();
  s.mean_ns = sum_.load(std::memory_order_relaxed) / static_cast<int64_t>(s.count);
  s.p50_ns = quantile(0.50);
  s.p99_ns = quantile(0.99);
  s.p999_ns = quantile(0.999);
  return s;
}

void CycleStats::request_reset() noexcept {
  wake_latency_.rebase();
  work_.rebase();
  reset_requested_.fetch_add(1, std::memory_order_release);
}

void CycleStats::apply_pending_reset() noexcept {
  const auto requested = reset_requested_.load(std::memory_order_acquire);
  if (requested == reset_applied_.load(std::memory_order_relaxed)) return;
  wake_latency_.restart_scalars();
  work_.restart_scalars();
  cycles_.store(0, std::memory_order_relaxed);
  overruns_.store(0, std::memory_order_relaxed);
  skipped_.store(0, std::memory_order_relaxed);
  reset_applied_.store(requested, std::memory_order_release);
}

CycleStatsSnapshot CycleStats::snapshot() const noexcept {
  CycleStatsSnapshot s;
  s.reset_generation = reset_applied_.load(std::memory_order_acquire);
  s.cycles = cycles_.load(std::memory_order_relaxed);
  s.overruns = overruns_.load(std::memory_order_relaxed);
  s.skipped_cycles = skipped_.load(std::memory_order_relaxed);
  s.wake_latency = wake_latency_.summary();
  s.work = work_.summary();
  return s;
}

}  // namespace ds1928
