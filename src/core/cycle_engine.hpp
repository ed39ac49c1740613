// The cycle engine: the one real-time thread of the daemon. It wakes on an absolute timeline
// (cycle n starts at t0 + n·period), runs the cycle's work, and keeps the statistics that say
// how well it kept time. See docs/realtime.md.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <system_error>
#include <thread>

#include "core/cycle_config.hpp"
#include "core/cycle_stats.hpp"
#include "core/rt_setup.hpp"

namespace ds1928 {

// The clock the timeline is aligned to, and what its steps did (written by the cycle thread).
struct TimebaseStatus {
  TimebaseKind kind = TimebaseKind::Monotonic;
  int64_t tai_offset_ns = 0;  // CLOCK_TAI − CLOCK_MONOTONIC the timeline follows (tai only)
  uint32_t steps = 0;         // re-anchors after a step of the aligned clock
  int64_t last_step_ns = 0;   // how far the last re-anchor moved the cycle starts
};

// What the cycle thread knows when a cycle starts.
struct CycleContext {
  uint64_t index = 0;    // grid index: start_ns == t0 + index·period (skipped slots leave gaps)
  int64_t start_ns = 0;  // nominal start, CLOCK_MONOTONIC
  int64_t woke_ns = 0;   // when the thread actually got going, CLOCK_MONOTONIC
  // The timeline: start_ns == t0_ns + index·period. It moves only when a step of the aligned
  // clock re-anchors it (cycle.timebase: tai); the shared memory's time base publishes it.
  int64_t t0_ns = 0;
  const struct TimebaseStatus* timebase = nullptr;  // what the timeline is aligned to
};

// The work of one cycle, implemented by the daemon (bus exchange, decoding, publishing...).
// Called on the cycle thread only; must not allocate, lock a mutex or block.
struct CycleTask {
  virtual ~CycleTask() = default;
  virtual void run_cycle(const CycleContext& ctx) noexcept = 0;
};

enum class CycleErrc {
  AlreadyRunning = 1,
  InvalidPeriod,      // period_us is 0 or above 1 s
  InvalidPriority,    // rt_priority outside 1..99
  InvalidCpu,         // cpu is neither -1 nor a CPU this process may run on
  InvalidSpin,        // spin_us not shorter than the period
  ThreadStartFailed,  // the cycle thread could not be created
  AffinityFailed,     // pinning the cycle thread to the configured CPU failed
};
[[nodiscard]] const std::error_category& cycle_category() noexcept;
[[nodiscard]] std::error_code make_error_code(CycleErrc e) noexcept;

// Outcome of start()/run_cycles(). `warning` is non-empty the first time the engine had to run
// without real-time guarantees (the caller logs it); later starts do not repeat it.
struct [[nodiscard]] CycleStartResult {
  std::error_code error;
  std::string warning;
  explicit operator bool() const noexcept { return !error; }
};

class CycleEngine {
 public:
  // Size of the stack touched by the cycle thread before its first cycle.
  static constexpr std::size_t kPrefaultStackBytes = 256 * 1024;

  CycleEngine(const CycleConfig& config, CycleTask& task) noexcept;
  ~CycleEngine();
  CycleEngine(const CycleEngine&) = delete;
  CycleEngine& operator=(const CycleEngine&) = delete;

  // Checks a configuration without starting anything.
  [[nodiscard]] static std::error_code validate(const CycleConfig& config) noexcept;

  // Starts the cycle thread and returns once it has done its setup (scheduling, affinity,
  // stack), so realtime() and rt_status_text() are valid when this returns.
  CycleStartResult start();
  // Stops the cycle thread after its current cycle and joins it. Idempotent.
  void stop() noexcept;
  // Runs exactly `cycles` executed cycles (skipped slots do not count) on the cycle thread
  // with the same setup as start(), and returns when they are done. For tests and benchmarks.
  CycleStartResult run_cycles(uint64_t cycles);

  [[nodiscard]] bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  // SCHED_FIFO in effect and, when lock_memory is set, memory locked.
  [[nodiscard]] bool realtime() const noexcept { return realtime_.load(std::memory_order_acquire); }
  // One line for the status: what is in effect, or why not. Read it from the thread that
  // calls start()/stop().
  [[nodiscard]] const std::string& rt_status_text() const noexcept { return status_text_; }
  // Cycles executed since construction (never reset).
  [[nodiscard]] uint64_t cycle_count() const noexcept {
    return cycle_count_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] CycleStatsSnapshot stats_snapshot() const noexcept { return stats_.snapshot(); }
  // How long cycle 0's work took (the start-up's one-time work; not counted as an overrun
  // however long it is); 0 before it ran.
  [[nodiscard]] int64_t first_cycle_work_ns() const noexcept {
    return first_cycle_work_ns_.load(std::memory_order_relaxed);
  }
  // Full histograms, for readers that want more than the summary (lock-free, any thread).
  [[nodiscard]] const CycleStats& stats() const noexcept { return stats_; }
  // The cycle thread zeroes the statistics between two cycles; snapshot().reset_generation
  // tells when it has happened.
  void request_stats_reset() noexcept { stats_.request_reset(); }
  [[nodiscard]] const CycleConfig& config() const noexcept { return config_; }
  [[nodiscard]] int64_t period_ns() const noexcept { return period_ns_; }

 private:
  enum class Setup : int { Pending = 0, Ready = 1, Failed = 2 };

  CycleStartResult launch(uint64_t cycle_limit);
  void thread_main() noexcept;
  void cycle_loop() noexcept;
  void compose_status();

  CycleConfig config_;
  CycleTask& task_;
  int64_t period_ns_ = 0;
  uint64_t cycle_limit_ = 0;  // 0 = until stop()

  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> stop_requested_{false};
  std::atomic<int> setup_{0};
  std::atomic<bool> realtime_{false};
  std::atomic<uint64_t> cycle_count_{0};
  std::atomic<int64_t> first_cycle_work_ns_{0};
  CycleStats stats_;
  TimebaseStatus timebase_;  // cycle thread

  // Setup outcome, written before setup_ is released, read after.
  int mlock_error_ = 0;
  int fifo_error_ = 0;
  int affinity_error_ = 0;
  std::size_t prefaulted_stack_ = 0;
  bool mlock_attempted_ = false;
  rt::CpuDmaLatencyHold dma_latency_;
  std::string status_text_;
  bool warned_ = false;
};

}  // namespace ds1928

template <>
struct std::is_error_code_enum<ds1928::CycleErrc> : std::true_type {};
