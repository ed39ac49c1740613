// Incidents: the moments the flight recorder keeps the frames around (docs/operations.md
// "Flight recorder"). Whoever sees one first raises it — a bus driver or the cycle work on the
// cycle thread, through an IncidentSink; the daemon's services on the normal thread directly —
// and the daemon's incident service writes the recorder's window around it to a file.
//
// The sink is the cycle thread's way out: a fixed single-producer/single-consumer queue inside
// the object (no heap), raise() never blocks, locks or calls the kernel; a full queue drops the
// incident and counts it. Producer: the cycle thread (a bus driver's exchange and the cycle work
// both run there). Consumer: the normal thread.
//
// A bus driver raises through BusDriver::raise_incident() (core/bus.hpp), which does nothing until
// the daemon gave the driver its sink (set_incident_sink, before the cycle thread starts). New
// kinds are added at the end of IncidentKind and of incident_kind_name()'s table.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string_view>

#include "core/clock.hpp"
#include "core/spsc_queue.hpp"

namespace ds1928 {

enum class IncidentKind : uint8_t {
  Manual = 0,       // `ds1928ctl incident mark TEXT`
  NodeLost,         // a node stopped answering (POWERLINK CN lost; CAN-I/O node silent)
  NodeReset,        // the master reset a node (POWERLINK: the MN's NMTResetNode, with reason)
  PresThreshold,    // POWERLINK: the loss-of-PRes threshold counter reached its threshold
  BusOff,           // CAN: the controller went bus-off
  NodeBootUp,       // CAN-I/O: a node's boot-up message (it restarted)
  HeartbeatMissed,  // CAN-I/O: a node's heartbeat did not come in time
  AxisError,        // an axis went to module_error
  AxisBusDown,      // an axis went to bus_down
  OverrunBurst,     // cycle overruns beyond flight_recorder.overrun_burst within one second
  ForeignMn,        // POWERLINK: another MN's SoC/PReq/SoA on the segment while running
};
inline constexpr std::size_t kIncidentKindCount = 11;

// "manual", "node_lost", ... (file names, journal, `ds1928ctl incidents`, metrics labels).
[[nodiscard]] constexpr std::string_view incident_kind_name(IncidentKind k) noexcept {
  constexpr std::string_view names[kIncidentKindCount] = {
      "manual",           "node_lost",  "node_reset",    "pres_threshold", "bus_off",   "boot_up",
      "heartbeat_missed", "axis_error", "axis_bus_down", "overrun_burst",  "foreign_mn"};
  const auto i = static_cast<std::size_t>(k);
  return i < kIncidentKindCount ? names[i] : std::string_view("unknown");
}

// One incident as raised: what, where (node and/or axis, -1: none), when (CLOCK_MONOTONIC).
struct IncidentEvent {
  IncidentKind kind = IncidentKind::Manual;
  int16_t node = -1;
  int16_t axis = -1;
  int64_t time_ns = 0;
};

class IncidentSink {
 public:
  static constexpr std::size_t kCapacity = 64;

  // Producer (cycle thread). `time_ns` 0: now. False (and counted) when the queue is full.
  bool raise(IncidentKind kind, int node = -1, int axis = -1, int64_t time_ns = 0) noexcept {
    const IncidentEvent e{kind, static_cast<int16_t>(node), static_cast<int16_t>(axis),
                          time_ns != 0 ? time_ns : rt::now_ns()};
    if (queue_.try_push(e)) return true;
    dropped_.store(dropped_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    return false;
  }
  // Consumer (normal thread).
  [[nodiscard]] std::optional<IncidentEvent> take() noexcept { return queue_.try_pop(); }
  // Any thread: incidents lost to a full queue (the normal thread did not take them in time).
  [[nodiscard]] uint64_t dropped() const noexcept {
    return dropped_.load(std::memory_order_relaxed);
  }

 private:
  SpscQueue<IncidentEvent, kCapacity> queue_;
  std::atomic<uint64_t> dropped_{0};
};

}  // namespace ds1928
