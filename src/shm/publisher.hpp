// The daemon's side of the shared memory (include/ds1928/shm.h): creates the objects at start,
// publishes every axis once per cycle from the cycle thread, removes the objects at exit.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <system_error>

#include "core/axis_sample.hpp"
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

// The usual classification of a cycle's sample: bus state first, then freshness, then
// ErrorInfo.
[[nodiscard]] constexpr AxisValidity classify(const AxisSample& sample, bool bus_up) noexcept {
  if (!bus_up) return AxisValidity::BusDown;
  if (!sample.fresh) return AxisValidity::Stale;
  if (sample.error_info != 0) return AxisValidity::ModuleError;
  return AxisValidity::Valid;
}

// What the cycle publishes for one axis.
struct AxisStatus {
  AxisSample sample;
  uint32_t endat_error = 0;    // last EnDat error word read from the module
  uint32_t endat_warning = 0;  // last EnDat warning word
  AxisValidity validity = AxisValidity::Stale;
};

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
  [[nodiscard]] std::error_code open(const ShmConfig& config, uint32_t axis_count,
                                     uint64_t cycle_period_ns);

  // Normal thread, after the cycle stopped: marks the object Stopped, wakes every waiter,
  // unmaps and unlinks both names (only if they still are ours). Idempotent.
  void close() noexcept;

  // Cycle thread, once per cycle. `cycle` must increase from call to call (the engine's cycle
  // index). Publishes min(axes.size(), axis_count) records, then the header, then bumps the
  // futex word, and wakes the slots whose factor divides a cycle index passed since the last
  // call — with one FUTEX_WAKE_BITSET, and only when a reader is registered. No allocation, no
  // lock, no other system call. The first publication sets the state to Running.
  void publish(uint64_t cycle, std::span<const AxisStatus> axes) noexcept;

  // Any thread.
  void set_state(DaemonState state) noexcept;

  [[nodiscard]] bool is_open() const noexcept { return header_ != nullptr; }
  [[nodiscard]] uint64_t generation() const noexcept { return generation_; }
  [[nodiscard]] uint32_t axis_count() const noexcept { return axis_count_; }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  // Futex wake-ups issued so far (for tests and statistics).
  [[nodiscard]] uint64_t wake_calls() const noexcept { return wake_calls_; }

 private:
  void wake(uint32_t mask) noexcept;

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
  uint64_t prev_cycle_ = 0;
  uint64_t publish_count_ = 0;
  uint64_t wake_calls_ = 0;
};

}  // namespace ds1928::shm
