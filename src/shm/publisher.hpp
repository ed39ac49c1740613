// The daemon's side of the shared memory (include/ds1928/shm.h): creates the objects at start,
// publishes every axis once per cycle from the cycle thread, removes the objects at exit.
#pragma once

#include <pthread.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <span>
#include <string>
#include <system_error>
#include <vector>

#include "core/axis_info.hpp"
#include "core/axis_sample.hpp"
#include "core/cycle_engine.hpp"
#include "ds1928/shm.h"
#include "shm/shm_config.hpp"

namespace ds1928::shm {

enum class DaemonState : uint32_t {
  Starting = DS1928_DAEMON_STARTING,
  Running = DS1928_DAEMON_RUNNING,
  Stopping = DS1928_DAEMON_STOPPING,
  Stopped = DS1928_DAEMON_STOPPED,
};

enum class AxisValidity : uint8_t {
  Valid = DS1928_AXIS_VALID,
  Stale = DS1928_AXIS_STALE,
  BusDown = DS1928_AXIS_BUS_DOWN,
  ModuleError = DS1928_AXIS_MODULE_ERROR,
};

// The usual classification of a cycle's sample: bus state first, then the error bits that
// invalidate (x20ds1928/error_bits.hpp: faults by default), then freshness (a held position after
// an analogue error is not fresh). Warnings leave a fresh position valid.
[[nodiscard]] constexpr AxisValidity classify(const AxisSample& sample, bool bus_up,
                                              const ErrorAssessment& errors) noexcept {
  if (!bus_up) return AxisValidity::BusDown;
  if (errors.invalidate && (sample.fresh || sample.held)) return AxisValidity::ModuleError;
  if (!sample.fresh) return AxisValidity::Stale;
  return AxisValidity::Valid;
}

// What the cycle publishes for one axis.
struct AxisStatus {
  AxisSample sample;
  uint32_t endat_error = 0;    // last EnDat error word read from the module
  uint32_t endat_warning = 0;  // last EnDat warning word
  AxisValidity validity = AxisValidity::Stale;
  ErrorAssessment errors;  // the flags' fault / warning bits
  AxisInfo info;           // the additional-information channels (DS1928_SHM_FEATURE_INFO)
};

// The names of one axis' additional-information channels (axes[].info; empty: off).
using InfoNames = std::array<std::string, kInfoChannels>;

// Largest axis count the daemon will map (a record is 128 bytes).
inline constexpr uint32_t kMaxAxes = 1024;

class Publisher {
 public:
  Publisher() noexcept = default;
  ~Publisher() { close(); }
  Publisher(const Publisher&) = delete;
  Publisher& operator=(const Publisher&) = delete;

  // Normal thread, before the cycle starts. Replaces a leftover object of a dead daemon
  // under the same name (a live one is refused with ShmError::kNameInUse), creates
  // <name> with config.mode and <name>.wait with the same mode plus write where it grants read,
  // applies config.group, maps and pre-faults both. State afterwards: Starting.
  // `info_names`: per axis the channels' names for the names table (DS1928_SHM_FEATURE_INFO);
  // missing axes have none (longer names than DS1928_INFO_NAME_LEN - 1 are cut).
  [[nodiscard]] std::error_code open(const ShmConfig& config, uint32_t axis_count,
                                     uint64_t cycle_period_ns,
                                     std::span<const InfoNames> info_names = {});

  // Normal thread, after the cycle stopped: marks the object Stopped, wakes every waiter,
  // unmaps and unlinks both names (only if they still are ours). Idempotent.
  void close() noexcept;

  // Cycle thread, once per cycle. `cycle` must increase from call to call (the engine's cycle
  // index). Publishes min(axes.size(), axis_count) records, then the header, then bumps the
  // futex word. It never wakes a reader itself: the wake-up thread does (see below). No
  // allocation, no lock, and no system call, except one FUTEX_WAKE of the wake-up thread when a
  // reader registers while that thread is idle (no reader for a second). `next_wake_ns` is
  // when the cycle thread will wake for the next cycle (CLOCK_MONOTONIC; 0 = unknown): the
  // wake-up thread, when it shares the cycle thread's CPU, wakes at that instant too. The first
  // publication sets the state to Running.
  void publish(uint64_t cycle, std::span<const AxisStatus> axes, int64_t next_wake_ns = 0) noexcept;
  // The same, and the time base: the timeline (ctx.t0_ns, ctx.timebase), the publication's
  // offset from ctx.start_ns and each axis' acquisition-to-publication time, measured over
  // windows of kTimebaseWindow publications (the first results after 64 and 256).
  void publish(const CycleContext& ctx, std::span<const AxisStatus> axes,
               int64_t next_wake_ns = 0) noexcept;

  // Publications per measurement window of the time base, and the histogram's buckets.
  static constexpr uint32_t kTimebaseWindow = 1024;
  static constexpr uint32_t kOffsetBuckets = 1024;

  // Normal thread, after open(): the wake-up thread's scheduling. `rt_priority` 1..99 sets
  // SCHED_FIFO (the daemon uses one below the cycle thread's), 0 leaves it as it is; `cpu` >= 0
  // pins it to the cycle thread's CPU ("follow" mode: it runs right after the cycle thread goes
  // back to sleep), -1 leaves it free ("predict" mode: it sleeps until the predicted next
  // publication and then polls in short steps). Returns 0 or the errno of the first call that
  // failed (the thread keeps running with what it has).
  [[nodiscard]] int place_waker(int rt_priority, int cpu) noexcept;

  // Any thread.
  void set_state(DaemonState state) noexcept;

  [[nodiscard]] bool is_open() const noexcept { return header_ != nullptr; }
  [[nodiscard]] uint64_t generation() const noexcept { return generation_; }
  [[nodiscard]] uint32_t axis_count() const noexcept { return axis_count_; }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  // FUTEX_WAKE_BITSET calls made for readers so far, all by the wake-up thread (for tests and
  // statistics).
  [[nodiscard]] uint64_t wake_calls() const noexcept {
    return wake_calls_.load(std::memory_order_relaxed);
  }
  // System calls publish() made: one per idle -> active transition of the wake-up thread.
  [[nodiscard]] uint64_t doorbell_calls() const noexcept {
    return doorbell_calls_.load(std::memory_order_relaxed);
  }
  // True while the wake-up thread follows the publications (a reader registered within the
  // last second); false while it sleeps until the cycle thread rings it.
  [[nodiscard]] bool waker_active() const noexcept {
    return !waker_idle_.load(std::memory_order_acquire);
  }
  // Usable stack of the wake-up thread (locked in RAM under mlockall): it only runs the loop
  // below and one futex call.
  static constexpr std::size_t kWakerStackBytes = 64 * 1024;

 private:
  void wake(uint32_t mask) noexcept;
  [[nodiscard]] bool start_waker() noexcept;
  void stop_waker() noexcept;
  void waker_main() noexcept;
  [[nodiscard]] bool any_waiter() const noexcept;
  [[nodiscard]] uint32_t due_mask(uint64_t seen_cycle, uint64_t last) const noexcept;
  void publish_records(uint64_t cycle, std::span<const AxisStatus> axes, int64_t now) noexcept;
  void publish_header(uint64_t cycle, int64_t now, int64_t next_wake_ns) noexcept;
  void measure(const CycleContext& ctx, int64_t now) noexcept;
  static void* waker_entry(void* self) noexcept;

  std::string name_;
  std::string wait_name_;
  ds1928_shm_header* header_ = nullptr;
  ds1928_shm_axis* records_ = nullptr;
  ds1928_shm_wait_area* wait_ = nullptr;
  std::size_t size_ = 0;
  int fd_ = -1;
  int wait_fd_ = -1;
  uint32_t axis_count_ = 0;
  uint64_t generation_ = 0;
  int64_t period_ns_ = 0;
  uint64_t prev_cycle_ = 0;
  uint64_t publish_count_ = 0;

  // Time base measurement (cycle thread; sized at open()). The offset histogram's buckets are
  // period / kOffsetBuckets wide; an offset past the period lands in the last one.
  std::vector<uint32_t> offset_hist_;
  int64_t offset_bucket_ns_ = 1;
  uint32_t window_count_ = 0;
  int64_t window_max_ns_ = 0;
  bool first_window_ = true;
  std::vector<uint32_t> acq_max_;  // per axis, this window
  int64_t published_t0_ = 0;

  // The wake-up thread and what the cycle thread tells it. Written by publish(), read by the
  // waker: plain atomics, no read-modify-write except on the idle -> active transition.
  pthread_t waker_{};
  bool waker_started_ = false;
  std::atomic<bool> waker_follows_{false};  // pinned to the cycle thread's CPU
  std::atomic<bool> waker_stop_{false};
  std::atomic<bool> waker_idle_{false};      // sleeping on doorbell_
  std::atomic<uint32_t> doorbell_{0};        // private futex word of the idle waker
  std::atomic<uint64_t> resume_after_{0};    // cycle before the publication that rang
  std::atomic<int64_t> next_wake_ns_{0};     // the cycle thread's next wake-up (0 unknown)
  std::atomic<int64_t> next_publish_ns_{0};  // predicted next publication
  std::atomic<uint64_t> wake_calls_{0};
  std::atomic<uint64_t> doorbell_calls_{0};
};

}  // namespace ds1928::shm
