// The control socket's place, permissions and limits (docs/configuration.md `socket:`).
#pragma once

#include <cstdint>
#include <string>

namespace ds1928 {

struct SocketConfig {
  std::string path = "/run/ds1928d/control.sock";
  uint32_t mode = 0660;
  std::string group;
  std::string privileged_group = "ds1928-admin";  // may send commands that change the encoder
  uint32_t max_clients = 64;
  uint32_t max_request_bytes = 4096;
  uint32_t idle_timeout_ms = 60000;
  // Replies a client has not read yet: past this many bytes no more of its requests are read
  // (back-pressure), and a client that leaves them unread for reply_stall_timeout_ms is closed.
  uint32_t reply_buffer_bytes = 262144;
  uint32_t reply_stall_timeout_ms = 10000;
};

}  // namespace ds1928
