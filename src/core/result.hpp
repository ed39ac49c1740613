// The project's expected-like result type (std::expected is C++23): a value or a
// std::error_code, no exceptions. Every layer (POWERLINK, CAN-I/O, EnDat, ...) returns it with
// errors of its own std::error_category; an error-code enum of any layer converts implicitly
// through that layer's make_error_code (found by argument-dependent lookup).
#pragma once

#include <optional>
#include <system_error>
#include <type_traits>
#include <utility>

namespace ds1928 {

template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}     // NOLINT(google-explicit-constructor)
  Result(std::error_code error) : error_(error) {}  // NOLINT(google-explicit-constructor)
  template <class E, std::enable_if_t<std::is_error_code_enum_v<E>, int> = 0>
  Result(E error) : error_(make_error_code(error)) {}  // NOLINT(google-explicit-constructor)

  [[nodiscard]] bool has_value() const noexcept { return value_.has_value(); }
  explicit operator bool() const noexcept { return has_value(); }
  // Precondition: has_value() (value() on an error is undefined, as with std::optional's *).
  [[nodiscard]] const T& value() const& noexcept { return *value_; }
  [[nodiscard]] T& value() & noexcept { return *value_; }
  [[nodiscard]] const T& operator*() const& noexcept { return *value_; }
  [[nodiscard]] const T* operator->() const noexcept { return &*value_; }
  // Default-constructed (no error) when has_value().
  [[nodiscard]] std::error_code error() const noexcept { return error_; }

 private:
  std::optional<T> value_;
  std::error_code error_;
};

}  // namespace ds1928
