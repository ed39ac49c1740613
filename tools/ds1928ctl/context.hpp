// What every ds1928ctl command shares: the global options and the exit codes.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace ds1928::ctl {

// Exit codes (also in `ds1928ctl --help` and docs/socket-protocol.md).
enum Exit : int {
  kOk = 0,
  kDaemonError = 1,  // the daemon answered {"ok":false,...}
  kUsage = 2,        // bad command line
  kUnavailable = 3,  // cannot connect to the socket / no shared memory / daemon gone
  kBadReply = 4,     // the daemon's reply was not valid protocol
  kNotValid = 5,     // --check: an axis is not valid (stale, bus_down, module_error)
};

inline constexpr const char* kDefaultSocket = "/run/ds1928d/control.sock";
inline constexpr const char* kDefaultShm = "/ds1928d";

struct Context {
  // -s; empty: $DS1928_SOCKET, else kDefaultSocket.
  std::string socket_path;
  // --shm; empty: the name the daemon reports (status' shm.name), else kDefaultShm.
  std::string shm_name;
  bool json = false;
  int timeout_ms = 10000;  // per request
  // Where the daemon is looked for, in order (resolve_sockets(): the chosen path, then the
  // per-user fallback the daemon uses when it cannot create the chosen one's directory).
  std::vector<std::string> sockets;
  // The socket was named (-s or $DS1928_SOCKET): a non-default instance.
  bool socket_named = false;
  // Set by the chosen subcommand's callback, run by main() after parsing.
  std::function<int()> action;
};

// Fills ctx.sockets and ctx.socket_named from -s, `env_socket` ($DS1928_SOCKET, may be null)
// and the default: -s > $DS1928_SOCKET > /run/ds1928d/control.sock, each followed by its
// fallback (ds1928::fallback_socket_path()).
void resolve_sockets(Context& ctx, const char* env_socket);

}  // namespace ds1928::ctl
