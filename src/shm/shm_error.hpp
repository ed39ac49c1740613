// Errors of the shared-memory publisher besides the system's own (errno values come back in
// std::system_category).
#pragma once

#include <system_error>

namespace ds1928::shm {

enum class ShmError {
  kInvalidName = 1,  // not "/name" without further slashes, or too long
  kNoAxes,           // axis count 0
  kTooManyAxes,      // more axes than the layout allows
  kUnknownGroup,     // ShmConfig.group names no group
  kNameInUse,        // another live daemon publishes under this name
  kNotRegularFile,   // a symbolic link, FIFO or other non-regular file holds the name
  kForeignOwner,     // a file of another user holds the name
};

[[nodiscard]] const std::error_category& shm_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(ShmError e) noexcept {
  return {static_cast<int>(e), shm_category()};
}

}  // namespace ds1928::shm

template <>
struct std::is_error_code_enum<ds1928::shm::ShmError> : std::true_type {};
