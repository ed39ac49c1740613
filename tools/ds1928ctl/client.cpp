#include "client.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <optional>
#include <vector>

#include "config/config_loader.hpp"

namespace ds1928::ctl {
namespace {

// The largest reply the daemon sends is a few hundred kB (axes of a full bus); more without a
// newline is not a ds1928d reply.
constexpr std::size_t kMaxReplyBytes = 16 * 1024 * 1024;

class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }

 private:
  int fd_;
};

std::string errno_text() {
  return std::strerror(errno);
}

// Connects to the first of ctx.sockets that accepts; -1 with `out` naming every path tried.
int connect_first(const Context& ctx, Outcome& out) {
  std::vector<std::string> paths = ctx.sockets;
  if (paths.empty()) paths.push_back(ctx.socket_path.empty() ? kDefaultSocket : ctx.socket_path);
  std::string tried;
  bool absent = true;  // every path: nothing there, or a stale socket
  for (const std::string& path : paths) {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof(addr.sun_path)) {
      out = {kUsage, nullptr, "socket path too long: " + path};
      return -1;
    }
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    const int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) {
      out = {kUnavailable, nullptr, "socket: " + errno_text()};
      return -1;
    }
    if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) return fd;
    absent = absent && (errno == ENOENT || errno == ECONNREFUSED);
    tried += (tried.empty() ? "" : ", nor to ") + path + " (" + errno_text() + ")";
    ::close(fd);
  }
  out = {
      kUnavailable, nullptr,
      "cannot connect to " + tried +
          (absent ? ": is ds1928d running? (-s PATH or $DS1928_SOCKET for another instance)" : "")};
  return -1;
}

// Connects and sends `request` as one line; the socket, or -1 with `out` set.
int connect_and_send(const Context& ctx, const nlohmann::json& request, Outcome& out) {
  const int fd = connect_first(ctx, out);
  if (fd < 0) return -1;
  const std::string line = request.dump() + "\n";
  for (std::size_t off = 0; off < line.size();) {
    const ssize_t n = ::send(fd, line.data() + off, line.size() - off, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) continue;
      out = {kUnavailable, nullptr, "send: " + errno_text()};
      ::close(fd);
      return -1;
    }
    off += static_cast<std::size_t>(n);
  }
  return fd;
}

// Checks a reply line and fills `out` (exit, reply, problem).
void take_reply(const std::string& text, Outcome& out) {
  out.reply = nlohmann::json::parse(text, nullptr, false);
  if (out.reply.is_discarded() || !out.reply.is_object() || !out.reply.contains("ok") ||
      !out.reply["ok"].is_boolean()) {
    out = {kBadReply, nullptr, "invalid reply from the daemon: " + text};
    return;
  }
  out.exit = kOk;
  if (out.reply["ok"] == true) return;
  // value() throws on a non-object or a non-string member: look before taking.
  const auto field = [](const nlohmann::json& j, const char* key, const char* fallback) {
    const auto it = j.is_object() ? j.find(key) : j.end();
    return it != j.end() && it->is_string() ? it->get<std::string>() : std::string(fallback);
  };
  const auto err = out.reply.find("error");
  const nlohmann::json none = nlohmann::json::object();
  const nlohmann::json& e = err != out.reply.end() ? *err : none;
  out.exit = kDaemonError;
  out.problem = field(e, "code", "error") + ": " + field(e, "message", "");
}

}  // namespace

void resolve_sockets(Context& ctx, const char* env_socket) {
  std::string chosen = ctx.socket_path;
  ctx.socket_named = !chosen.empty();
  if (chosen.empty() && env_socket != nullptr && *env_socket != '\0') {
    chosen = env_socket;
    ctx.socket_named = true;
  }
  if (chosen.empty()) chosen = kDefaultSocket;
  ctx.sockets = {chosen};
  if (std::string fallback = fallback_socket_path(chosen); fallback != chosen)
    ctx.sockets.push_back(std::move(fallback));
}

// One recv() into `buffer` once poll() said the socket is readable: empty when bytes (or an
// EINTR) came, else the failure (closed, error, a line longer than kMaxReplyBytes). Shared by
// the single-reply and the streaming request.
std::optional<Outcome> receive_into(const Fd& fd, std::string& buffer) {
  char chunk[65536];
  const ssize_t n = ::recv(fd.get(), chunk, sizeof(chunk), 0);
  if (n < 0) {
    if (errno == EINTR) return std::nullopt;
    return Outcome{kUnavailable, nullptr, "receive: " + errno_text()};
  }
  if (n == 0)
    return Outcome{kUnavailable, nullptr, "the daemon closed the connection without a reply"};
  buffer.append(chunk, static_cast<std::size_t>(n));
  if (buffer.size() > kMaxReplyBytes && buffer.find('\n') == std::string::npos)
    return Outcome{
        kBadReply, nullptr,
        "line longer than " + std::to_string(kMaxReplyBytes) + " bytes without a newline"};
  return std::nullopt;
}

Outcome send_request(const Context& ctx, const nlohmann::json& request) {
  Outcome out;
  const int raw = connect_and_send(ctx, request, out);
  if (raw < 0) return out;
  Fd fd(raw);

  std::string buffer;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(ctx.timeout_ms);
  for (;;) {
    if (const auto nl = buffer.find('\n'); nl != std::string::npos) {
      buffer.resize(nl);
      break;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                          deadline - std::chrono::steady_clock::now())
                          .count();
    if (left <= 0)
      return {kUnavailable, nullptr, "no reply within " + std::to_string(ctx.timeout_ms) + " ms"};
    pollfd p{fd.get(), POLLIN, 0};
    const int r = poll(&p, 1, static_cast<int>(left));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return {kUnavailable, nullptr, "poll: " + errno_text()};
    if (r == 0) continue;
    if (auto failed = receive_into(fd, buffer)) return *failed;
  }
  take_reply(buffer, out);
  return out;
}

StreamOutcome stream_request(const Context& ctx, const nlohmann::json& request,
                             const std::function<bool(const nlohmann::json&)>& on_line,
                             const std::function<void()>& idle) {
  Outcome out;
  const int raw = connect_and_send(ctx, request, out);
  if (raw < 0) return out;
  Fd fd(raw);
  std::string buffer;
  std::size_t scanned = 0;
  for (;;) {
    for (auto nl = buffer.find('\n', scanned); nl != std::string::npos;
         nl = buffer.find('\n', scanned)) {
      const std::string_view text(buffer.data() + scanned, nl - scanned);
      scanned = nl + 1;
      nlohmann::json line = nlohmann::json::parse(text, nullptr, false);
      if (line.is_discarded() || !line.is_object())
        return {kBadReply, nullptr, "invalid line from the daemon: " + std::string(text)};
      if (line.contains("ok")) {
        take_reply(std::string(text), out);
        return out;
      }
      try {
        if (!on_line(line)) return {kUnavailable, nullptr, "stopped"};
      } catch (const std::exception& e) {
        return {kBadReply, nullptr, std::string("invalid line from the daemon: ") + e.what()};
      }
    }
    buffer.erase(0, scanned);
    scanned = 0;
    idle();
    pollfd p{fd.get(), POLLIN, 0};
    const int r = poll(&p, 1, 200);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return {kUnavailable, nullptr, "poll: " + errno_text()};
    if (r == 0) continue;
    if (auto failed = receive_into(fd, buffer)) return *failed;
  }
}

std::string shm_name_for(const Context& ctx, std::string& problem) {
  if (!ctx.shm_name.empty()) return ctx.shm_name;
  Context ask = ctx;
  ask.timeout_ms = std::min(ctx.timeout_ms, 3000);
  const Outcome o = send_request(ask, {{"cmd", "status"}});
  if (o.exit == kOk) {
    const auto shm = o.reply.find("shm");
    if (shm != o.reply.end() && shm->is_object()) {
      const auto name = shm->find("name");
      if (name != shm->end() && name->is_string() && !name->get<std::string>().empty())
        return name->get<std::string>();
    }
  }
  if (!ctx.socket_named) return kDefaultShm;  // the default instance, or none: the default name
  problem = "cannot ask the daemon for its shared memory name (" +
            (o.exit == kOk ? std::string("its status names none") : o.problem) +
            "); give --shm NAME";
  return {};
}

int print_outcome(const Context& ctx, const Outcome& o, const HumanPrinter& print_human) {
  if (o.exit == kDaemonError && ctx.json) {
    std::cout << o.reply.dump() << std::endl;  // scripts get the error object too
  }
  if (o.exit != kOk) {
    std::cerr << "ds1928ctl: " << (o.exit == kDaemonError ? "error: " : "") << o.problem << "\n";
    return o.exit;
  }
  if (ctx.json) {
    std::cout << o.reply.dump() << std::endl;
  } else {
    try {
      print_human(o.reply);
    } catch (const std::exception& e) {
      std::cerr << "ds1928ctl: unexpected reply (" << e.what()
                << "): " << o.reply.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)
                << "\n";
      return kBadReply;
    }
  }
  return kOk;
}

int request_and_print(const Context& ctx, const nlohmann::json& request,
                      const HumanPrinter& print_human) {
  return print_outcome(ctx, send_request(ctx, request), print_human);
}

}  // namespace ds1928::ctl
