// Per-cycle statistics of the cycle engine: fixed-size histograms written by the cycle thread
// alone and read by any other thread without locks.
//
// Writer discipline: exactly one thread (the cycle thread) calls record()/apply_pending_reset().
// Every word is a relaxed atomic updated with load+store (no read-modify-write, so no locked bus
// cycle on the hot path). A reader sees each word torn-free but not the set of words as one
// instant: a summary may mix the state of two consecutive cycles, which for a distribution of
// thousands of samples is irrelevant, and costs the writer nothing.
//
// A reset never zeroes the bins on the cycle thread (256 KiB, tens of µs): the thread that asks
// for it copies the bins into a baseline that readers subtract, and the cycle thread only
// restarts the handful of scalar counters and extremes between two cycles.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

namespace ds1928 {

// What a reader gets from a histogram. Quantiles are the upper edge of the bin that holds the
// quantile (so they never understate), clamped to the exact maximum; a quantile that falls in
// the overflow bin reports the exact maximum.
struct HistogramSummary {
  uint64_t count = 0;
  uint64_t overflow = 0;  // samples ≥ LatencyHistogram::kRangeNs
  int64_t min_ns = 0;
  int64_t max_ns = 0;
  int64_t mean_ns = 0;
  int64_t p50_ns = 0;
  int64_t p99_ns = 0;
  int64_t p999_ns = 0;
};

// Durations from 0 to kRangeNs in kBinWidthNs bins, plus an overflow bin and the exact min/max.
// Negative inputs count as 0 (a clock read racing the deadline by a few ns).
class LatencyHistogram {
 public:
  static constexpr int64_t kBinWidthNs = 250;
  static constexpr std::size_t kBins = 16384;  // 0 .. 4.096 ms
  static constexpr int64_t kRangeNs = kBinWidthNs * static_cast<int64_t>(kBins);

  LatencyHistogram() noexcept;
  LatencyHistogram(const LatencyHistogram&) = delete;
  LatencyHistogram& operator=(const LatencyHistogram&) = delete;

  // Writer side.
  void record(int64_t ns) noexcept;
  // Restarts count, sum, minimum and maximum (a few stores); the bins restart by rebase().
  void restart_scalars() noexcept;

  // Requester side (the thread that asks for a reset, before the writer's restart_scalars()):
  // the current bins become the baseline, so they read as zero from now on.
  void rebase() noexcept;

  // Reader side (any thread). Bin counts are since the last rebase().
  [[nodiscard]] HistogramSummary summary() const noexcept;
  // Value at quantile q (0 < q ≤ 1) by the rule of HistogramSummary; 0 when empty.
  [[nodiscard]] int64_t quantile(double q) const noexcept;
  [[nodiscard]] uint64_t bin(std::size_t i) const noexcept {
    return since_base(bins_[i], base_[i]);
  }
  [[nodiscard]] uint64_t overflow() const noexcept { return since_base(overflow_, overflow_base_); }
  [[nodiscard]] int64_t max_ns() const noexcept { return max_.load(std::memory_order_relaxed); }

 private:
  static void bump(std::atomic<uint64_t>& a) noexcept {
    a.store(a.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  // Counts only grow, so a count below its baseline is a reader racing a rebase(): zero.
  static uint64_t since_base(const std::atomic<uint64_t>& count,
                             const std::atomic<uint64_t>& base) noexcept {
    const uint64_t b = base.load(std::memory_order_relaxed);
    const uint64_t c = count.load(std::memory_order_relaxed);
    return c > b ? c - b : 0;
  }

  std::array<std::atomic<uint64_t>, kBins> bins_;
  std::array<std::atomic<uint64_t>, kBins> base_;
  std::atomic<uint64_t> overflow_{0};
  std::atomic<uint64_t> overflow_base_{0};
  std::atomic<uint64_t> count_{0};
  std::atomic<int64_t> sum_{0};
  std::atomic<int64_t> min_{0};
  std::atomic<int64_t> max_{0};
};

// Everything the engine reports, as plain values.
struct CycleStatsSnapshot {
  uint64_t cycles = 0;            // cycles run since the last reset
  uint64_t overruns = 0;          // cycles whose work ran past the next cycle start
  uint64_t skipped_cycles = 0;    // grid slots left out to get back onto the timeline
  uint64_t reset_generation = 0;  // how many resets the cycle thread has applied
  HistogramSummary wake_latency;  // woke − nominal start
  HistogramSummary work;          // duration of CycleTask::run_cycle (the exchange and its work)
};

// The engine's live statistics. One instance per engine, written by its cycle thread only.
class CycleStats {
 public:
  // Writer side (cycle thread).
  void record_cycle(int64_t wake_latency_ns, int64_t work_ns) noexcept {
    wake_latency_.record(wake_latency_ns);
    work_.record(work_ns);
    bump(cycles_);
  }
  void record_overrun(uint64_t skipped) noexcept {
    bump(overruns_);
    skipped_.store(skipped_.load(std::memory_order_relaxed) + skipped, std::memory_order_relaxed);
  }
  // Applies a pending reset request, if any. Called by the cycle thread between cycles, so the
  // reset never races the writer and needs no lock.
  void apply_pending_reset() noexcept;

  // Any thread other than the writer (one at a time): asks for a reset. The histograms restart
  // at once (this call copies their bins into the baseline); cycles, overruns, counts and
  // extremes restart when the writer applies the request between two cycles.
  void request_reset() noexcept;

  // Reader side (any thread).
  [[nodiscard]] CycleStatsSnapshot snapshot() const noexcept;
  [[nodiscard]] const LatencyHistogram& wake_latency() const noexcept { return wake_latency_; }
  [[nodiscard]] const LatencyHistogram& work() const noexcept { return work_; }

 private:
  static void bump(std::atomic<uint64_t>& a) noexcept {
    a.store(a.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }

  LatencyHistogram wake_latency_;
  LatencyHistogram work_;
  std::atomic<uint64_t> cycles_{0};
  std::atomic<uint64_t> overruns_{0};
  std::atomic<uint64_t> skipped_{0};
  std::atomic<uint64_t> reset_requested_{0};
  std::atomic<uint64_t> reset_applied_{0};
};

}  // namespace ds1928
