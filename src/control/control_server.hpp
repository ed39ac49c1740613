// The daemon's command socket: a Unix stream socket carrying one JSON object per line, request
// and reply (docs/socket-protocol.md). Runs on an io_context the daemon owns and runs on its
// normal-priority thread; commands are handlers the daemon registers by name.
//
//   control::Server server(io, config.socket);
//   server.add_command("status", [&](const control::Request& req, control::Reply reply) {
//     reply.ok({{"daemon", {...}}});
//   });
//   if (auto ec = server.start()) ...;
//
// A handler may complete at once or keep the Reply and complete it later from any thread (an
// EnDat command finishes many cycles later); reply.cancelled() tells it the client is gone.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>

#include "control/socket_config.hpp"

namespace boost::asio {
class io_context;
}

namespace ds1928::control {

// The peer of a connection as the kernel reports it (SO_PEERCRED), taken at accept time.
struct PeerCredentials {
  pid_t pid = 0;
  uid_t uid = static_cast<uid_t>(-1);
  gid_t gid = static_cast<gid_t>(-1);
};

// The error codes the server itself produces; handlers may add their own codes (a short
// snake_case word, documented in docs/socket-protocol.md).
enum class ErrorCode {
  BadJson,          // not JSON, or not a JSON object
  RequestTooLarge,  // a line longer than SocketConfig.max_request_bytes
  UnknownCommand,   // "cmd" names no registered command
  BadArgument,      // an argument is missing or of the wrong type/range (message names it)
  TooManyClients,   // SocketConfig.max_clients connections are open already
  IdleTimeout,      // no request for SocketConfig.idle_timeout_ms
  Internal,         // the handler failed
};
[[nodiscard]] std::string_view to_string(ErrorCode code) noexcept;

// Thrown by the Request argument accessors; the server answers it with bad_argument.
class ArgumentError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One parsed request, valid for the duration of the handler call (copy what you keep).
class Request {
 public:
  Request(std::string command, const nlohmann::json& body, const PeerCredentials& peer)
      : command_(std::move(command)), body_(body), peer_(peer) {}

  [[nodiscard]] const std::string& command() const noexcept { return command_; }
  // The whole request object ("cmd", "id" and the arguments).
  [[nodiscard]] const nlohmann::json& body() const noexcept { return body_; }
  [[nodiscard]] const PeerCredentials& peer() const noexcept { return peer_; }
  [[nodiscard]] bool has(std::string_view name) const { return body_.contains(name); }

  // Typed arguments. Missing (for the required forms), wrong type or out of range throws
  // ArgumentError naming the argument and the expected type.
  [[nodiscard]] uint64_t get_uint(std::string_view name, uint64_t max = UINT64_MAX) const;
  [[nodiscard]] std::optional<uint64_t> opt_uint(std::string_view name,
                                                 uint64_t max = UINT64_MAX) const;
  [[nodiscard]] int64_t get_int(std::string_view name) const;
  [[nodiscard]] std::optional<int64_t> opt_int(std::string_view name) const;
  [[nodiscard]] std::string get_string(std::string_view name) const;
  [[nodiscard]] std::optional<std::string> opt_string(std::string_view name) const;
  [[nodiscard]] bool get_bool(std::string_view name) const;
  [[nodiscard]] std::optional<bool> opt_bool(std::string_view name) const;

 private:
  std::string command_;
  const nlohmann::json& body_;
  PeerCredentials peer_;
};

namespace detail {
struct ReplyState;
}

// Completes one request. Cheap to copy; the first completion wins, later ones are ignored.
// Callable from any thread. If every copy is dropped without completion, the client gets an
// "internal" error.
class Reply {
 public:
  explicit Reply(std::shared_ptr<detail::ReplyState> state) : state_(std::move(state)) {}

  // {"ok":true, <fields>..., "id": <echo>}. `fields` must be an object (or null).
  void ok(nlohmann::json fields = nlohmann::json::object()) const;
  // {"ok":false, "error":{"code":..., "message":...}, "id": <echo>}.
  void error(std::string_view code, std::string message) const;
  void error(ErrorCode code, std::string message) const {
    error(to_string(code), std::move(message));
  }

  // The client disconnected before the reply: completing is harmless but useless.
  [[nodiscard]] bool cancelled() const noexcept;
  [[nodiscard]] bool done() const noexcept;
  // Called once, on the server's thread, when the client disconnects before completion (at
  // once if it already did).
  void on_cancel(std::function<void()> callback) const;

  // Server thread only. Sends `line` (an object; the request's "id" is added) to the client as
  // an intermediate line before the reply, for commands that stream (capture). False, and
  // nothing sent, when the client is gone, the request is complete, or the client's unread
  // output has reached SocketConfig.reply_buffer_bytes: the caller keeps the data and tries
  // again later (back-pressure).
  [[nodiscard]] bool progress(nlohmann::json line) const;

 private:
  std::shared_ptr<detail::ReplyState> state_;
};

using Handler = std::function<void(const Request&, Reply)>;

class Server {
 public:
  Server(boost::asio::io_context& io, SocketConfig config);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Registers (or replaces) a command. Server thread (or before start()).
  void add_command(std::string name, Handler handler);

  // Creates the socket's directory if missing, replaces a stale socket file (a live server on
  // the path: errc::address_in_use), binds, applies mode and group, listens.
  [[nodiscard]] std::error_code start();
  // Closes the listener and every connection (pending replies become cancelled), removes the
  // socket file. Server thread. Idempotent.
  void stop();

  [[nodiscard]] std::size_t client_count() const noexcept;
  [[nodiscard]] const std::string& path() const noexcept;

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace ds1928::control
