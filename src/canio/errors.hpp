// Error codes of the CAN-I/O port layer (own std::error_category) and a small expected-like
// result type: codecs and ports return a value or a named error, never throw.
#pragma once

#include <cstdint>
#include <optional>
#include <system_error>
#include <type_traits>
#include <utility>

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

// Expected-like result: a value or an error_code, no exceptions.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}     // NOLINT(google-explicit-constructor)
  Result(std::error_code error) : error_(error) {}  // NOLINT(google-explicit-constructor)
  template <class E, std::enable_if_t<std::is_error_code_enum_v<E>, int> = 0>
  Result(E error) : error_(make_error_code(error)) {}  // NOLINT(google-explicit-constructor)

  [[nodiscard]] bool has_value() const noexcept { return value_.has_value(); }
  explicit operator bool() const noexcept { return has_value(); }
  // Precondition: has_value().
  [[nodiscard]] const T& value() const& noexcept { return *value_; }
  [[nodiscard]] T& value() & noexcept { return *value_; }
  [[nodiscard]] const T& operator*() const noexcept { return *value_; }
  [[nodiscard]] const T* operator->() const noexcept { return &*value_; }
  [[nodiscard]] std::error_code error() const noexcept { return error_; }

 private:
  std::optional<T> value_;
  std::error_code error_;
};

}  // namespace ds1928::canio

namespace std {
template <>
struct is_error_code_enum<ds1928::canio::CanError> : true_type {};
}  // namespace std
