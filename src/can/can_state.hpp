// Error-confinement state of a CAN controller as the port reports it (ISO 11898-1 states plus the
// two netdev states "stopped" and "down"). Same order of severity as the kernel's enum can_state
// (linux/can/netlink.h) so the netlink value maps one to one.
#pragma once

#include <cstdint>
#include <string_view>

namespace ds1928::canio {

enum class CanState : uint8_t {
  ErrorActive = 0,   // TEC and REC below 96: normal operation
  ErrorWarning = 1,  // a counter reached 96: still sending, the bus is marginal
  ErrorPassive = 2,  // a counter reached 128: the node only sends passive error flags
  BusOff = 3,        // TEC reached 256: the controller left the bus until restarted
  Stopped = 4,       // the controller is stopped (interface configured down by the driver)
  Sleeping = 5,      // controller in sleep mode
  Down = 6,          // the network interface is administratively down or gone
  Unknown = 7,       // not yet known (netlink not read, no error frame seen)
};

[[nodiscard]] constexpr std::string_view to_string(CanState s) noexcept {
  switch (s) {
    case CanState::ErrorActive:
      return "error-active";
    case CanState::ErrorWarning:
      return "error-warning";
    case CanState::ErrorPassive:
      return "error-passive";
    case CanState::BusOff:
      return "bus-off";
    case CanState::Stopped:
      return "stopped";
    case CanState::Sleeping:
      return "sleeping";
    case CanState::Down:
      return "down";
    case CanState::Unknown:
      return "unknown";
  }
  return "?";
}

// True when frames can be sent (error-active, warning or passive).
[[nodiscard]] constexpr bool can_transmit(CanState s) noexcept {
  return s == CanState::ErrorActive || s == CanState::ErrorWarning || s == CanState::ErrorPassive;
}

}  // namespace ds1928::canio
