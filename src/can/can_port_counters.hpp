// What every CAN port counts, kept once: the relaxed atomic counters a port bumps from its sending
// and receiving threads, the snapshot CanPort::counters() returns, the counting of a decoded error
// frame, and the check of a filter table every port applies before taking it.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <system_error>

#include "can/can_error_frame.hpp"
#include "can/can_frame.hpp"
#include "can/can_port.hpp"
#include "can/errors.hpp"

namespace ds1928::canio {

inline void bump(std::atomic<uint64_t>& c) noexcept {
  c.fetch_add(1, std::memory_order_relaxed);
}

// The atomic twin of CanPortCounters (one field each, same meaning).
struct AtomicCanPortCounters {
  std::atomic<uint64_t> tx_frames{0}, tx_queue_full{0}, tx_interface_down{0}, tx_bus_off{0},
      tx_invalid{0}, tx_errors{0}, rx_frames{0}, rx_error_frames{0}, rx_kernel_drops{0},
      rx_unstamped{0}, rx_errors{0}, bus_off_events{0}, restarts{0}, protocol_errors{0},
      controller_errors{0}, tx_timeouts{0}, no_ack{0};

  // A decoded error frame's events, each in its counter.
  void count_error_event(const CanErrorEvent& e) noexcept {
    if (e.bus_off) bump(bus_off_events);
    if (e.restarted) bump(restarts);
    if (e.protocol) bump(protocol_errors);
    if (e.controller) bump(controller_errors);
    if (e.tx_timeout) bump(tx_timeouts);
    if (e.no_ack) bump(no_ack);
  }

  [[nodiscard]] CanPortCounters snapshot() const noexcept {
    auto r = [](const std::atomic<uint64_t>& a) { return a.load(std::memory_order_relaxed); };
    CanPortCounters c;
    c.tx_frames = r(tx_frames);
    c.tx_queue_full = r(tx_queue_full);
    c.tx_interface_down = r(tx_interface_down);
    c.tx_bus_off = r(tx_bus_off);
    c.tx_invalid = r(tx_invalid);
    c.tx_errors = r(tx_errors);
    c.rx_frames = r(rx_frames);
    c.rx_error_frames = r(rx_error_frames);
    c.rx_kernel_drops = r(rx_kernel_drops);
    c.rx_unstamped = r(rx_unstamped);
    c.rx_errors = r(rx_errors);
    c.bus_off_events = r(bus_off_events);
    c.restarts = r(restarts);
    c.protocol_errors = r(protocol_errors);
    c.controller_errors = r(controller_errors);
    c.tx_timeouts = r(tx_timeouts);
    c.no_ack = r(no_ack);
    return c;
  }
};

// A filter table a port can take: at most `max_filters` entries (kTooManyFilters), each
// identifier in range for its format (kInvalidFrame).
[[nodiscard]] inline std::error_code check_filters(std::span<const CanIdFilter> ids,
                                                   std::size_t max_filters) noexcept {
  if (ids.size() > max_filters) return CanError::kTooManyFilters;
  for (const CanIdFilter& f : ids)
    if (f.id > (f.extended ? kMaxExtendedId : kMaxStandardId)) return CanError::kInvalidFrame;
  return {};
}

}  // namespace ds1928::canio
