// What every ds1928ctl command shares: the global options and the exit codes.
#pragma once

#include <functional>
#include <string>

namespace ds1928::ctl {

// Exit codes (also in `ds1928ctl --help` and docs/socket-protocol.md).
enum Exit : int {
  kOk = 0,
  kDaemonError = 1,  // the daemon answered {"ok":false,...}
  kUsage = 2,        // bad command line
  kUnavailable = 3,  // cannot connect to the socket / no shared memory / daemon gone
  kBadReply = 4,     // the daemon's reply was not valid protocol
};

struct Context {
  std::string socket_path = "/run/ds1928d/control.sock";
  std::string shm_name = "/ds1928d";
  bool json = false;
  int timeout_ms = 10000;  // per request
  // Set by the chosen subcommand's callback, run by main() after parsing.
  std::function<int()> action;
};

}  // namespace ds1928::ctl
