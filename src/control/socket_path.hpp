// Where the control socket may be created: the checks Server::start makes on the socket's path
// before it binds, so that the daemon (often root, or the service user with capabilities) never
// follows a planted symbolic link, never removes or adopts a file someone else owns, and never
// listens in a directory where another user could swap the socket for their own.
#pragma once

#include <string>
#include <system_error>

namespace ds1928::control {

enum class SocketPathError {
  kDirectoryMissing = 1,  // the directory does not exist and could not be created
  kDirectoryIsLink,       // the directory is a symbolic link
  kDirectoryNotOwned,     // the directory belongs to another user (neither us nor root)
  kDirectoryWritable,     // others may write to the directory and it has no sticky bit
  kNotSocket,             // a symbolic link or another non-socket file is at the path
  kForeignSocket,         // a socket of another user is at the path
};

[[nodiscard]] const std::error_category& socket_path_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(SocketPathError e) noexcept {
  return {static_cast<int>(e), socket_path_category()};
}

// True for the errors that mean "this directory is not ours to use" (the daemon may try its
// per-user fallback directory), false for those that mean "someone put something here" (the
// daemon must refuse to start, not move elsewhere).
[[nodiscard]] bool directory_unusable(const std::error_code& ec) noexcept;

// Creates the directory of `path` if missing (mode 0755 for new levels), checks it and whatever
// is at `path`; removes a stale socket of ours nobody listens on. Returns {} when `path` is free
// to bind, std::errc::address_in_use when a daemon listens on it.
[[nodiscard]] std::error_code prepare_socket_path(const std::string& path);

}  // namespace ds1928::control

template <>
struct std::is_error_code_enum<ds1928::control::SocketPathError> : std::true_type {};
