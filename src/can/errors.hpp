// Error codes of the CAN-I/O port layer (own std::error_category): codecs and ports return a
// Result (core/result.hpp), a value or a named error, never throw.
#pragma once

#include <cstdint>
#include <system_error>
#include <type_traits>

#include "core/result.hpp"

namespace ds1928::canio {

enum class CanError : int {
  // Frames and error frames.
  kNotAnErrorFrame = 1,  // decode_error_frame() got a data or remote frame
  kErrorFrameLength,     // error frame whose dlc is not 8
  kUnknownErrorClass,    // error class bits this code does not know
  kInvalidFrame,         // identifier out of range for its format, dlc above 8, or error flag
  // Ports.
  kNoCanSupport,          // socket(AF_CAN) fails: the kernel has no CAN (EAFNOSUPPORT)
  kNoSuchInterface,       // no network interface of that name
  kNotCanInterface,       // the interface exists but is not a CAN device
  kInterfaceDown,         // the interface is down (ENETDOWN) or its controller stopped
  kBusOff,                // the controller is bus-off: nothing can be sent until it restarts
  kBitrateMismatch,       // interface bit rate differs from the configuration
  kTooManyFilters,        // more identifiers than the port's fixed filter table holds
  kInterfaceNameInvalid,  // empty, or longer than IFNAMSIZ-1
  kNetlink,               // rtnetlink answer missing or malformed
  kNotOpen,               // the port is not open
  kVirtualBusMismatch,    // a shared virtual bus of that name has another layout/version
};

[[nodiscard]] const std::error_category& can_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(CanError e) noexcept {
  return {static_cast<int>(e), can_category()};
}

}  // namespace ds1928::canio

namespace std {
template <>
struct is_error_code_enum<ds1928::canio::CanError> : true_type {};
}  // namespace std
