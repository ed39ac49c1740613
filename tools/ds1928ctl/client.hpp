// Talking to the daemon's control socket: one request line, one reply line.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "context.hpp"

namespace ds1928::ctl {

struct Outcome {
  int exit = kOk;        // Exit code
  nlohmann::json reply;  // the parsed reply when exit is kOk or kDaemonError
  std::string problem;   // what went wrong, for stderr
};

// Connects to ctx.socket_path, sends `request` as one line, reads one reply line.
[[nodiscard]] Outcome send_request(const Context& ctx, const nlohmann::json& request);

// A request whose reply is preceded by intermediate lines (capture): every line without "ok"
// goes to `on_line` (false from it: stop, the connection is closed: exit kUnavailable with no
// problem text); `idle` is called at least every 200 ms while waiting. No reply timeout: the
// stream lasts as long as the daemon sends. Returns like send_request once the reply arrives.
using StreamOutcome = Outcome;
[[nodiscard]] StreamOutcome stream_request(
    const Context& ctx, const nlohmann::json& request,
    const std::function<bool(const nlohmann::json&)>& on_line, const std::function<void()>& idle);

// The common case of a command: send, then on {"ok":true} print the reply (as one JSON line
// with --json, else through `print_human`), on {"ok":false} print "error: <code>: <message>" to
// stderr. Returns the exit code. A new command group needs nothing more than this.
using HumanPrinter = std::function<void(const nlohmann::json& reply)>;
[[nodiscard]] int request_and_print(const Context& ctx, const nlohmann::json& request,
                                    const HumanPrinter& print_human);
// The printing half of request_and_print, for a command that looks at the reply afterwards.
[[nodiscard]] int print_outcome(const Context& ctx, const Outcome& o,
                                const HumanPrinter& print_human);

// The shared memory name to read: --shm, else the name the daemon reports in its status, else
// /ds1928d when the daemon was not named and cannot be asked. Empty with `problem` set when a
// named daemon (-s, $DS1928_SOCKET) cannot be asked.
[[nodiscard]] std::string shm_name_for(const Context& ctx, std::string& problem);

}  // namespace ds1928::ctl
