#include "control/socket_path.hpp"

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace ds1928::control {
namespace {

class SocketPathCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "ds1928.socket_path"; }
  std::string message(int value) const override {
    switch (static_cast<SocketPathError>(value)) {
      case SocketPathError::kDirectoryMissing:
        return "its directory does not exist and cannot be created";
      case SocketPathError::kDirectoryIsLink:
        return "its directory is a symbolic link; refusing to follow it";
      case SocketPathError::kDirectoryNotOwned:
        return "its directory belongs to another user, who could replace the socket; refusing "
               "to use it";
      case SocketPathError::kDirectoryWritable:
        return "its directory is writable by others without the sticky bit, so the socket "
               "could be replaced; refusing to use it";
      case SocketPathError::kNotSocket:
        return "a symbolic link or a file that is not a socket is in the way; refusing to "
               "follow or replace it (remove it if it is not meant to be there)";
      case SocketPathError::kForeignSocket:
        return "a socket of another user is in the way; refusing to remove it (remove it if "
               "it is not meant to be there)";
    }
    return "unknown socket path error";
  }
};

std::error_code errno_code() noexcept {
  return {errno, std::system_category()};
}

// A daemon accepts connections on `path` (a stale socket refuses them).
bool someone_listens(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  const bool connected = ::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0;
  ::close(fd);
  return connected;
}

std::error_code check_directory(const std::filesystem::path& dir) {
  std::error_code fs_ec;
  std::filesystem::create_directories(dir, fs_ec);
  struct stat st {};
  if (lstat(dir.c_str(), &st) != 0)
    return errno == ENOENT ? SocketPathError::kDirectoryMissing : errno_code();
  if (S_ISLNK(st.st_mode)) return SocketPathError::kDirectoryIsLink;
  if (!S_ISDIR(st.st_mode)) return std::make_error_code(std::errc::not_a_directory);
  if (st.st_uid != geteuid() && st.st_uid != 0) return SocketPathError::kDirectoryNotOwned;
  if ((st.st_mode & (S_IWGRP | S_IWOTH)) != 0 && (st.st_mode & S_ISVTX) == 0)
    return SocketPathError::kDirectoryWritable;
  return {};
}

}  // namespace

const std::error_category& socket_path_category() noexcept {
  static const SocketPathCategory category;
  return category;
}

bool directory_unusable(const std::error_code& ec) noexcept {
  if (ec == SocketPathError::kDirectoryMissing) return true;
  if (ec.category() != std::system_category()) return false;
  return ec.value() == EACCES || ec.value() == EPERM || ec.value() == EROFS || ec.value() == ENOENT;
}

std::error_code prepare_socket_path(const std::string& path) {
  if (path.empty() || path.size() >= sizeof(sockaddr_un::sun_path))
    return std::make_error_code(std::errc::filename_too_long);
  const auto dir = std::filesystem::path(path).parent_path();
  if (!dir.empty()) {
    if (auto ec = check_directory(dir)) return ec;
  }
  struct stat st {};
  if (lstat(path.c_str(), &st) != 0) return errno == ENOENT ? std::error_code{} : errno_code();
  if (!S_ISSOCK(st.st_mode)) return SocketPathError::kNotSocket;
  if (st.st_uid != geteuid()) return SocketPathError::kForeignSocket;
  if (someone_listens(path)) return std::make_error_code(std::errc::address_in_use);
  if (::unlink(path.c_str()) != 0) return errno_code();  // stale: ours, nobody listens
  return {};
}

}  // namespace ds1928::control
