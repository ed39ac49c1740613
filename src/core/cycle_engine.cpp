#include "core/cycle_engine.hpp"

#include <pthread.h>

#include <cerrno>
#include <string>
#include <system_error>

#include "core/clock.hpp"
#include "core/timebase.hpp"

namespace ds1928 {

namespace {

class CycleCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "ds1928.cycle"; }
  [[nodiscard]] std::string message(int ev) const override {
    switch (static_cast<CycleErrc>(ev)) {
      case CycleErrc::AlreadyRunning:
        return "the cycle engine is already running";
      case CycleErrc::InvalidPeriod:
        return "cycle.period_us must be 1..1000000";
      case CycleErrc::InvalidPriority:
        return "cycle.rt_priority must be 1..99";
      case CycleErrc::InvalidCpu:
        return "cycle.cpu must be -1 or a CPU this process is allowed to run on";
      case CycleErrc::InvalidSpin:
        return "cycle.spin_us must be shorter than cycle.period_us";
      case CycleErrc::ThreadStartFailed:
        return "the cycle thread could not be created";
      case CycleErrc::AffinityFailed:
        return "the cycle thread could not be pinned to its CPU";
    }
    return "unknown cycle engine error";
  }
};

}  // namespace

const std::error_category& cycle_category() noexcept {
  static const CycleCategory category;
  return category;
}

std::error_code make_error_code(CycleErrc e) noexcept {
  return {static_cast<int>(e), cycle_category()};
}

CycleEngine::CycleEngine(const CycleConfig& config, CycleTask& task) noexcept
    : config_(config), task_(task), period_ns_(int64_t{config.period_us} * 1000) {}

CycleEngine::~CycleEngine() {
  stop();
}

std::error_code CycleEngine::validate(const CycleConfig& config) noexcept {
  if (config.period_us == 0 || config.period_us > 1'000'000) return CycleErrc::InvalidPeriod;
  if (config.rt_priority < 1 || config.rt_priority > 99) return CycleErrc::InvalidPriority;
  if (config.cpu != -1 && !rt::cpu_usable(config.cpu)) return CycleErrc::InvalidCpu;
  if (config.spin_us >= config.period_us) return CycleErrc::InvalidSpin;
  return {};
}

CycleStartResult CycleEngine::start() {
  return launch(0);
}

CycleStartResult CycleEngine::run_cycles(uint64_t cycles) {
  if (cycles == 0) return {};
  auto result = launch(cycles);
  if (result) {
    thread_.join();  // the thread leaves its loop after `cycles` cycles
    dma_latency_.release();
  }
  return result;
}

CycleStartResult CycleEngine::launch(uint64_t cycle_limit) {
  CycleStartResult result;
  if (running()) {
    result.error = CycleErrc::AlreadyRunning;
    return result;
  }
  if (auto ec = validate(config_)) {
    result.error = ec;
    return result;
  }
  if (thread_.joinable()) thread_.join();  // finished run_cycles() leftovers

  // mlockall is process-wide, so it is done here on the caller's thread, before the cycle
  // thread's stack exists (MCL_FUTURE then locks that stack as it is mapped).
  mlock_attempted_ = config_.lock_memory;
  mlock_error_ = config_.lock_memory ? rt::lock_all_memory().error : 0;
  if (config_.hold_cpu_dma_latency) (void)dma_latency_.acquire();

  cycle_limit_ = cycle_limit;
  stop_requested_.store(false, std::memory_order_relaxed);
  setup_.store(static_cast<int>(Setup::Pending), std::memory_order_relaxed);
  running_.store(true, std::memory_order_release);
  try {
    thread_ = std::thread([this] { thread_main(); });
  } catch (const std::system_error&) {
    running_.store(false, std::memory_order_release);
    dma_latency_.release();
    result.error = CycleErrc::ThreadStartFailed;
    return result;
  }
  setup_.wait(static_cast<int>(Setup::Pending), std::memory_order_acquire);
  if (setup_.load(std::memory_order_acquire) == static_cast<int>(Setup::Failed)) {
    thread_.join();
    dma_latency_.release();
    result.error = CycleErrc::AffinityFailed;
    compose_status();
    return result;
  }
  compose_status();
  if (!realtime() && !warned_) {
    warned_ = true;
    result.warning = status_text_;
  }
  return result;
}

void CycleEngine::stop() noexcept {
  stop_requested_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  dma_latency_.release();
}

void CycleEngine::thread_main() noexcept {
  affinity_error_ = config_.cpu >= 0 ? rt::pin_to_cpu(config_.cpu).error : 0;
  if (affinity_error_ != 0) {
    running_.store(false, std::memory_order_release);
    setup_.store(static_cast<int>(Setup::Failed), std::memory_order_release);
    setup_.notify_all();
    return;
  }
  fifo_error_ = rt::set_fifo_priority(config_.rt_priority).error;
  prefaulted_stack_ = rt::prefault_stack(kPrefaultStackBytes);
  pthread_setname_np(pthread_self(), "ds1928-cycle");
  realtime_.store(fifo_error_ == 0 && mlock_error_ == 0, std::memory_order_release);
  setup_.store(static_cast<int>(Setup::Ready), std::memory_order_release);
  setup_.notify_all();

  cycle_loop();
  running_.store(false, std::memory_order_release);
}

void CycleEngine::cycle_loop() noexcept {
  const int64_t period = period_ns_;
  const int64_t spin = int64_t{config_.spin_us} * 1000;
  const bool tai = config_.timebase == TimebaseKind::Tai;
  TaiTimeline tai_timeline(period);
  // One period of margin so that cycle 0 is not already late when the setup took a while; with
  // the tai timebase, cycle 0 is the first TAI multiple of the period after that.
  int64_t t0 =
      tai ? tai_timeline.anchor(rt::now_ns(), measure_tai_offset()) : rt::now_ns() + period;
  timebase_ = TimebaseStatus{};
  timebase_.kind = config_.timebase;
  timebase_.tai_offset_ns = tai ? tai_timeline.tai_offset() : 0;
  uint64_t index = 0;
  uint64_t executed = 0;

  while (!stop_requested_.load(std::memory_order_relaxed)) {
    const int64_t start = t0 + static_cast<int64_t>(index) * period;
    const int64_t woke = rt::sleep_until(start, spin);
    task_.run_cycle(CycleContext{index, start, woke, t0, &timebase_});
    int64_t end = rt::now_ns();

    stats_.apply_pending_reset();
    stats_.record_cycle(woke - start, end - woke);
    cycle_count_.store(cycle_count_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);

    ++index;
    if (index == 1) {
      // Cycle 0 does the start-up's one-time work (the bus' first exchange, the first touch of
      // the shared memory and of every code path): its length is reported on its own
      // (first_cycle_work_ns) and the grid starts one period after it, so that a start is not an
      // overrun and skipped slots at every boot. The grid moves by whole periods, so a TAI
      // timeline keeps its phase; there the index moves instead of t0, which stays the anchor.
      first_cycle_work_ns_.store(end - woke, std::memory_order_relaxed);
      if (end > t0 + period) {
        const int64_t periods = (end - t0) / period + 1;
        if (tai)
          index += static_cast<uint64_t>(periods);
        else
          t0 += periods * period;
      }
    }
    if (tai && tai_timeline.follow(measure_tai_offset()) != 0) {
      // A step of the TAI clock: the timeline moved by less than half a period; the index
      // continues, and a start now behind is skipped once (never a burst).
      t0 = tai_timeline.t0();
      timebase_.tai_offset_ns = tai_timeline.tai_offset();
      timebase_.steps = tai_timeline.steps();
      timebase_.last_step_ns = tai_timeline.last_step_ns();
      end = rt::now_ns();
      if (t0 + static_cast<int64_t>(index) * period <= end)
        index = static_cast<uint64_t>((end - t0) / period) + 1;
    }
    const int64_t next = t0 + static_cast<int64_t>(index) * period;
    if (end > next) {
      // The work ran into the next slot: resume at the first slot still ahead, on the same
      // grid, so that one long cycle never shifts every later one.
      const auto first_future = static_cast<uint64_t>((end - t0) / period) + 1;
      stats_.record_overrun(first_future - index);
      index = first_future;
    }
    if (cycle_limit_ != 0 && ++executed >= cycle_limit_) break;
  }
}

void CycleEngine::compose_status() {
  std::string s;
  if (affinity_error_ != 0) {
    s = "not running: pinning to CPU " + std::to_string(config_.cpu) + " failed (" +
        rt::errno_text(affinity_error_) + ")";
    status_text_ = std::move(s);
    return;
  }
  const bool rt_ok = realtime();
  s = rt_ok ? "real-time: " : "not real-time: ";
  if (fifo_error_ == 0) {
    s += "SCHED_FIFO " + std::to_string(config_.rt_priority);
  } else {
    s += "SCHED_FIFO " + std::to_string(config_.rt_priority) + " refused (" +
         rt::errno_text(fifo_error_) + "), normal priority";
  }
  s += config_.cpu >= 0 ? ", CPU " + std::to_string(config_.cpu) : ", any CPU";
  if (mlock_attempted_) {
    s += mlock_error_ == 0 ? ", memory locked"
                           : ", mlockall refused (" + rt::errno_text(mlock_error_) + ")";
  } else {
    s += ", memory not locked (lock_memory off)";
  }
  switch (dma_latency_.state()) {
    case rt::CpuDmaLatencyHold::State::Held:
      s += ", cpu_dma_latency held at 0";
      break;
    case rt::CpuDmaLatencyHold::State::Absent:
      s += ", no /dev/cpu_dma_latency";
      break;
    case rt::CpuDmaLatencyHold::State::Failed:
      s += ", /dev/cpu_dma_latency not held (" + rt::errno_text(dma_latency_.error()) + ")";
      break;
    case rt::CpuDmaLatencyHold::State::Off:
      break;
  }
  if (prefaulted_stack_ < kPrefaultStackBytes)
    s += ", stack pre-faulted " + std::to_string(prefaulted_stack_ / 1024) + " of " +
         std::to_string(kPrefaultStackBytes / 1024) + " KiB (thread stack too small)";
  if (config_.spin_us > 0) s += ", spin " + std::to_string(config_.spin_us) + " us";
  if (!rt_ok) s += "; cycle timing is best effort";
  status_text_ = std::move(s);
}

}  // namespace ds1928
