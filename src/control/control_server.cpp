#include "control/control_server.hpp"

#include <grp.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <atomic>
#include <deque>
#include <filesystem>
#include <map>
#include <set>

#include "control/asio.hpp"
#include "control/request_parser.hpp"
#include "control/socket_path.hpp"

namespace ds1928::control {

namespace asio = boost::asio;
using local = asio::local::stream_protocol;
using json = nlohmann::json;

std::string_view to_string(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::BadJson:
      return "bad_json";
    case ErrorCode::RequestTooLarge:
      return "request_too_large";
    case ErrorCode::UnknownCommand:
      return "unknown_command";
    case ErrorCode::BadArgument:
      return "bad_argument";
    case ErrorCode::TooManyClients:
      return "too_many_clients";
    case ErrorCode::IdleTimeout:
      return "idle_timeout";

    case ErrorCode::Internal:
      return "internal";
  }
  return "internal";
}

namespace {

// Deeper than any request of docs/socket-protocol.md needs; bounds the recursion of copying and
// dumping an echoed "id" whatever the client sends.
constexpr unsigned kMaxJsonDepth = 64;
// Messages quote what the client sent: a bounded prefix of it.
constexpr std::size_t kMaxQuoted = 160;

std::string bounded(std::string text, std::size_t max = kMaxQuoted) {
  if (text.size() <= max) return text;
  const std::size_t total = text.size();
  text.resize(max);
  return text + "... (" + std::to_string(total) + " bytes)";
}

// The byte offset where `line` nests deeper than `max` arrays/objects, if it does. Brackets in
// strings do not count; the JSON parser reports every other malformation.
std::optional<std::size_t> too_deep(std::string_view line, unsigned max) {
  unsigned depth = 0;
  bool in_string = false;
  bool escaped = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (in_string) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max) return i;
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return std::nullopt;
}

json error_reply(std::string_view code, std::string message) {
  return json{{"ok", false}, {"error", {{"code", code}, {"message", std::move(message)}}}};
}

std::string type_name(const json& v) {
  if (v.is_number_unsigned()) return "unsigned integer";
  if (v.is_number_integer()) return "negative integer";
  return v.type_name();
}

[[noreturn]] void bad_type(std::string_view name, std::string_view expected, const json& v) {
  throw ArgumentError("argument '" + std::string(name) + "': expected " + std::string(expected) +
                      ", got " + type_name(v));
}

[[noreturn]] void missing(std::string_view name, std::string_view expected) {
  throw ArgumentError("argument '" + std::string(name) + "' (" + std::string(expected) +
                      ") is required");
}

}  // namespace

// ---- Request arguments --------------------------------------------------------------------

std::optional<uint64_t> Request::opt_uint(std::string_view name, uint64_t max) const {
  const auto it = body_.find(name);
  if (it == body_.end()) return std::nullopt;
  const std::string expected = "unsigned integer 0.." + std::to_string(max);
  if (!it->is_number_unsigned()) {
    if (it->is_number_integer())
      throw ArgumentError("argument '" + std::string(name) + "': expected " + expected + ", got " +
                          it->dump());
    bad_type(name, expected, *it);
  }
  const uint64_t v = it->get<uint64_t>();
  if (v > max)
    throw ArgumentError("argument '" + std::string(name) + "': expected " + expected + ", got " +
                        std::to_string(v));
  return v;
}
uint64_t Request::get_uint(std::string_view name, uint64_t max) const {
  if (auto v = opt_uint(name, max)) return *v;
  missing(name, "unsigned integer");
}
std::optional<int64_t> Request::opt_int(std::string_view name) const {
  const auto it = body_.find(name);
  if (it == body_.end()) return std::nullopt;
  if (it->is_number_integer() &&
      (!it->is_number_unsigned() || it->get<uint64_t>() <= static_cast<uint64_t>(INT64_MAX)))
    return it->get<int64_t>();
  bad_type(name, "integer", *it);
}
int64_t Request::get_int(std::string_view name) const {
  if (auto v = opt_int(name)) return *v;
  missing(name, "integer");
}
std::optional<std::string> Request::opt_string(std::string_view name) const {
  const auto it = body_.find(name);
  if (it == body_.end()) return std::nullopt;
  if (!it->is_string()) bad_type(name, "string", *it);
  return it->get<std::string>();
}
std::string Request::get_string(std::string_view name) const {
  if (auto v = opt_string(name)) return *v;
  missing(name, "string");
}
std::optional<bool> Request::opt_bool(std::string_view name) const {
  const auto it = body_.find(name);
  if (it == body_.end()) return std::nullopt;
  if (!it->is_boolean()) bad_type(name, "boolean", *it);
  return it->get<bool>();
}
bool Request::get_bool(std::string_view name) const {
  if (auto v = opt_bool(name)) return *v;
  missing(name, "boolean");
}

// ---- Sessions -------------------------------------------------------------------------------

class Session;

namespace detail {
// Shared by the copies of one Reply. The session only watches it (weak), so that dropping every
// copy without completing is noticed (destructor) and answered.
struct ReplyState {
  asio::io_context* io = nullptr;
  std::weak_ptr<Session> session;
  uint64_t serial = 0;  // which request of the session this answers
  json id;              // null: none
  std::atomic<bool> done{false};
  std::atomic<bool> cancelled{false};
  std::function<void()> on_cancel;  // server thread only

  ~ReplyState();
  void complete(json reply);
};
}  // namespace detail

class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(std::shared_ptr<Server::Impl> server, local::socket socket);
  void start();
  void close();
  void deliver(uint64_t serial, json reply);
  [[nodiscard]] bool progress(uint64_t serial, json line);

 private:
  void read_more();
  void on_read(const boost::system::error_code& ec, std::size_t n);
  void process_buffer();
  void handle_line(std::string_view line);
  void send(json reply, bool close_after);
  void write_next();
  void arm_idle_timer();
  // Back-pressure: no request is read or handled while this many reply bytes wait for the
  // client; the stall timer closes the connection when they keep waiting.
  [[nodiscard]] bool output_full() const noexcept;
  void on_output_drained();

  std::shared_ptr<Server::Impl> impl_;
  Server::Impl& server_;
  local::socket socket_;
  asio::steady_timer idle_timer_;
  asio::steady_timer stall_timer_;
  PeerCredentials peer_;
  std::string inbuf_;
  std::array<char, 4096> chunk_{};
  std::deque<std::pair<std::string, bool>> outq_;  // line, close after it
  std::size_t out_bytes_ = 0;                      // in outq_
  bool stall_armed_ = false;
  std::weak_ptr<detail::ReplyState> pending_state_;
  uint64_t pending_ = 0;  // serial of the request awaiting its reply, 0: none
  uint64_t serial_ = 0;
  bool reading_ = false;
  bool closed_ = false;
  bool closing_ = false;  // a final reply is queued
};

struct Server::Impl : std::enable_shared_from_this<Server::Impl> {
  asio::io_context& io;
  SocketConfig config;
  local::acceptor acceptor;
  asio::steady_timer accept_retry;
  bool accept_failing = false;  // logged once per run of failures
  std::map<std::string, Handler, std::less<>> commands;
  std::set<std::shared_ptr<Session>> sessions;
  bool listening = false;

  Impl(asio::io_context& io_, SocketConfig config_)
      : io(io_), config(std::move(config_)), acceptor(io_), accept_retry(io_) {}

  void accept();
  void reject(local::socket socket);
};

bool Session::output_full() const noexcept {
  return out_bytes_ >= server_.config.reply_buffer_bytes;
}

detail::ReplyState::~ReplyState() {
  if (done.load()) return;
  // Dropped without completion: the client still deserves an answer.
  json reply = error_reply(to_string(ErrorCode::Internal), "the command finished without a reply");
  if (!id.is_null()) reply["id"] = id;
  if (auto s = session.lock())
    asio::post(*io, [s, n = serial, reply = std::move(reply)]() mutable {
      s->deliver(n, std::move(reply));
    });
}

void detail::ReplyState::complete(json reply) {
  if (done.exchange(true)) return;
  if (!id.is_null()) reply["id"] = id;
  auto s = session.lock();
  if (!s || cancelled.load()) return;
  asio::post(*io, [s, n = serial, reply = std::move(reply)]() mutable {
    s->deliver(n, std::move(reply));
  });
}

Session::Session(std::shared_ptr<Server::Impl> server, local::socket socket)
    : impl_(std::move(server)),
      server_(*impl_),
      socket_(std::move(socket)),
      idle_timer_(server_.io),
      stall_timer_(server_.io) {
  ucred cred{};
  socklen_t len = sizeof(cred);
  if (getsockopt(socket_.native_handle(), SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0) {
    peer_.pid = cred.pid;
    peer_.uid = cred.uid;
    peer_.gid = cred.gid;
  }
}

void Session::start() {
  arm_idle_timer();
  read_more();
}

void Session::arm_idle_timer() {
  if (server_.config.idle_timeout_ms == 0) return;
  idle_timer_.expires_after(std::chrono::milliseconds(server_.config.idle_timeout_ms));
  idle_timer_.async_wait([self = weak_from_this()](const boost::system::error_code& ec) {
    auto s = self.lock();
    if (ec || !s || s->closed_ || s->pending_ || s->closing_) return;
    s->send(
        error_reply(to_string(ErrorCode::IdleTimeout),
                    "no request for " + std::to_string(s->server_.config.idle_timeout_ms) + " ms"),
        true);
  });
}

void Session::read_more() {
  if (reading_ || closed_ || closing_ || output_full()) return;
  // Back-pressure: while a request is pending, buffer at most one more request's worth.
  if (pending_ && inbuf_.size() > server_.config.max_request_bytes) return;
  reading_ = true;
  socket_.async_read_some(asio::buffer(chunk_),
                          [self = shared_from_this()](const boost::system::error_code& ec,
                                                      std::size_t n) { self->on_read(ec, n); });
}

void Session::on_read(const boost::system::error_code& ec, std::size_t n) {
  reading_ = false;
  if (closed_) return;
  if (ec) {  // EOF or error: the client is gone (mid-request or not)
    close();
    return;
  }
  inbuf_.append(chunk_.data(), n);
  if (!pending_) arm_idle_timer();
  process_buffer();
  read_more();
}

void Session::process_buffer() {
  const std::size_t limit = server_.config.max_request_bytes;
  while (!pending_ && !closing_ && !closed_ && !output_full()) {
    const auto nl = inbuf_.find('\n');
    if (nl == std::string::npos) {
      if (inbuf_.size() > limit) {
        // No way to find the next request boundary without reading the rest: give up.
        inbuf_.clear();
        send(error_reply(to_string(ErrorCode::RequestTooLarge),
                         "request longer than " + std::to_string(limit) + " bytes"),
             true);
      }
      return;
    }
    std::string line = inbuf_.substr(0, nl);
    inbuf_.erase(0, nl + 1);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.size() > limit) {
      send(error_reply(to_string(ErrorCode::RequestTooLarge),
                       "request of " + std::to_string(line.size()) + " bytes, limit " +
                           std::to_string(limit)),
           false);
      continue;
    }
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    handle_line(line);
  }
}

void Session::handle_line(std::string_view line) {
  if (const auto at = too_deep(line, kMaxJsonDepth)) {
    send(error_reply(to_string(ErrorCode::BadJson),
                     "nested deeper than " + std::to_string(kMaxJsonDepth) +
                         " arrays/objects (at byte " + std::to_string(*at) + ")"),
         false);
    return;
  }
  ParsedRequest parsed = parse_request(line);
  if (parsed.error) parsed.message = bounded(std::move(parsed.message));
  const json& id = parsed.id;
  auto fail = [&](ErrorCode code, std::string message) {
    json reply = error_reply(to_string(code), std::move(message));
    if (!id.is_null()) reply["id"] = id;
    send(std::move(reply), false);
  };
  if (parsed.error) return fail(*parsed.error, std::move(parsed.message));
  const std::string& name = parsed.command;
  const json& body = parsed.body;
  const auto handler = server_.commands.find(name);
  if (handler == server_.commands.end()) {
    std::string known;
    for (const auto& [n, h] : server_.commands) known += (known.empty() ? "" : ", ") + n;
    return fail(ErrorCode::UnknownCommand,
                "unknown command '" + bounded(name, 64) + "' (known: " + known + ")");
  }

  auto state = std::make_shared<detail::ReplyState>();
  state->io = &server_.io;
  state->session = weak_from_this();
  state->serial = ++serial_;
  state->id = id;
  pending_ = state->serial;
  pending_state_ = state;
  idle_timer_.cancel();
  Reply reply(std::move(state));
  // Nothing a handler throws reaches the io_context: the client gets the error, the daemon
  // goes on.
  try {
    handler->second(Request(name, body, peer_), reply);
  } catch (const ArgumentError& e) {
    reply.error(ErrorCode::BadArgument, bounded(e.what(), 2 * kMaxQuoted));
  } catch (const json::exception& e) {
    // A handler reading the request body beyond the typed accessors.
    reply.error(ErrorCode::BadArgument, "'" + name + "': " + bounded(e.what(), 2 * kMaxQuoted));
  } catch (const std::exception& e) {
    spdlog::warn("control command '{}' failed: {}", name, e.what());
    reply.error(ErrorCode::Internal, "'" + name + "' failed: " + bounded(e.what()));
  } catch (...) {
    spdlog::warn("control command '{}' failed with a non-standard exception", name);
    reply.error(ErrorCode::Internal, "'" + name + "' failed");
  }
}

void Session::deliver(uint64_t serial, json reply) {
  if (closed_ || serial != pending_) return;
  pending_ = 0;
  pending_state_.reset();
  send(std::move(reply), false);
  arm_idle_timer();
  process_buffer();
  read_more();
}

bool Session::progress(uint64_t serial, json line) {
  if (closed_ || closing_ || serial != pending_ || output_full()) return false;
  send(std::move(line), false);
  return true;
}

void Session::send(json reply, bool close_after) {
  if (closed_ || closing_) return;
  if (close_after) closing_ = true;
  outq_.emplace_back(reply.dump(-1, ' ', false, json::error_handler_t::replace) + "\n",
                     close_after);
  out_bytes_ += outq_.back().first.size();
  if (output_full() && !stall_armed_) {
    // The client does not read its replies: it gets reply_stall_timeout_ms to start again.
    stall_armed_ = true;
    stall_timer_.expires_after(std::chrono::milliseconds(server_.config.reply_stall_timeout_ms));
    stall_timer_.async_wait([self = weak_from_this()](const boost::system::error_code& ec) {
      auto s = self.lock();
      if (ec || !s || s->closed_ || !s->stall_armed_) return;
      spdlog::warn(
          "control client pid {} uid {}: {} bytes of replies unread for {} ms; connection closed",
          s->peer_.pid, s->peer_.uid, s->out_bytes_, s->server_.config.reply_stall_timeout_ms);
      s->close();
    });
  }
  if (outq_.size() == 1) write_next();
}

void Session::write_next() {
  if (outq_.empty() || closed_) return;
  asio::async_write(socket_, asio::buffer(outq_.front().first),
                    [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                      if (self->closed_) return;
                      const bool was_full = self->output_full();
                      const bool close_after = self->outq_.front().second;
                      self->out_bytes_ -= self->outq_.front().first.size();
                      self->outq_.pop_front();
                      if (ec || close_after) {
                        self->close();
                        return;
                      }
                      self->write_next();
                      if (was_full && !self->output_full()) self->on_output_drained();
                    });
}

void Session::on_output_drained() {
  stall_armed_ = false;
  stall_timer_.cancel();
  if (!pending_) arm_idle_timer();
  process_buffer();
  read_more();
}

void Session::close() {
  if (closed_) return;
  closed_ = true;
  boost::system::error_code ignored;
  idle_timer_.cancel();
  stall_timer_.cancel();
  socket_.shutdown(local::socket::shutdown_both, ignored);
  socket_.close(ignored);
  if (auto state = pending_state_.lock()) {
    state->cancelled = true;
    state->done = true;  // nobody to answer: no "internal" error when it is dropped either
    if (state->on_cancel) std::exchange(state->on_cancel, nullptr)();
  }
  pending_ = 0;
  pending_state_.reset();
  outq_.clear();
  out_bytes_ = 0;
  server_.sessions.erase(shared_from_this());
}

// ---- Reply ----------------------------------------------------------------------------------

void Reply::ok(json fields) const {
  json reply = json{{"ok", true}};
  if (fields.is_object()) {
    for (auto& [k, v] : fields.items()) reply[k] = std::move(v);
  } else if (!fields.is_null()) {
    reply["result"] = std::move(fields);
  }
  state_->complete(std::move(reply));
}

void Reply::error(std::string_view code, std::string message) const {
  state_->complete(error_reply(code, std::move(message)));
}

bool Reply::cancelled() const noexcept {
  return state_->cancelled.load();
}
bool Reply::done() const noexcept {
  return state_->done.load();
}

void Reply::on_cancel(std::function<void()> callback) const {
  auto state = state_;
  asio::post(*state->io, [state, callback = std::move(callback)]() mutable {
    if (state->cancelled.load()) {
      callback();
    } else if (!state->done.load()) {
      state->on_cancel = std::move(callback);
    }
  });
}

bool Reply::progress(json line) const {
  if (state_->done.load() || state_->cancelled.load()) return false;
  auto s = state_->session.lock();
  if (!s) return false;
  if (!state_->id.is_null()) line["id"] = state_->id;
  return s->progress(state_->serial, std::move(line));
}

// ---- Server ---------------------------------------------------------------------------------

void Server::Impl::accept() {
  acceptor.async_accept(
      [self = shared_from_this()](const boost::system::error_code& ec, local::socket socket) {
        if (!self->listening) return;
        if (ec) {
          // Out of file descriptors (EMFILE/ENFILE) or memory: the pending connection stays in
          // the backlog, so accepting again at once would spin. Retry shortly instead.
          if (!std::exchange(self->accept_failing, true))
            spdlog::warn("control socket: accept failed: {}; retrying every 100 ms", ec.message());
          self->accept_retry.expires_after(std::chrono::milliseconds(100));
          self->accept_retry.async_wait([self](const boost::system::error_code& e) {
            if (!e && self->listening) self->accept();
          });
          return;
        }
        if (std::exchange(self->accept_failing, false))
          spdlog::info("control socket: accepting connections again");
        if (self->sessions.size() >= self->config.max_clients) {
          self->reject(std::move(socket));
        } else {
          auto s = std::make_shared<Session>(self, std::move(socket));
          self->sessions.insert(s);
          s->start();
        }
        self->accept();
      });
}

void Server::Impl::reject(local::socket socket) {
  auto sock = std::make_shared<local::socket>(std::move(socket));
  auto line = std::make_shared<std::string>(
      error_reply(to_string(ErrorCode::TooManyClients),
                  std::to_string(config.max_clients) + " clients are connected already")
          .dump() +
      "\n");
  asio::async_write(*sock, asio::buffer(*line),
                    [sock, line](const boost::system::error_code&, std::size_t) {
                      boost::system::error_code ignored;
                      sock->shutdown(local::socket::shutdown_both, ignored);
                      sock->close(ignored);
                    });
}

Server::Server(asio::io_context& io, SocketConfig config)
    : impl_(std::make_shared<Impl>(io, std::move(config))) {}

Server::~Server() {
  stop();
}

void Server::add_command(std::string name, Handler handler) {
  impl_->commands[std::move(name)] = std::move(handler);
}

std::error_code Server::start() {
  auto& impl = *impl_;
  const std::string& path = impl.config.path;
  if (path.empty() || path.size() >= sizeof(sockaddr_un::sun_path))
    return std::make_error_code(std::errc::filename_too_long);
  gid_t gid = static_cast<gid_t>(-1);
  if (!impl.config.group.empty()) {
    group grp{};
    group* found = nullptr;
    std::vector<char> buffer(16384);
    if (getgrnam_r(impl.config.group.c_str(), &grp, buffer.data(), buffer.size(), &found) != 0 ||
        found == nullptr)
      return std::make_error_code(std::errc::invalid_argument);
    gid = found->gr_gid;
  }
  if (auto e = prepare_socket_path(path)) return e;

  boost::system::error_code ec;
  impl.acceptor.open(local(), ec);
  if (!ec) impl.acceptor.bind(local::endpoint(path), ec);
  if (ec) {
    boost::system::error_code ignored;
    impl.acceptor.close(ignored);
    return {ec.value(), std::system_category()};
  }
  // The socket takes the daemon's group; chown only to change it (the packaged unit's syscall
  // filter refuses chown, and its group already is the readers' group).
  struct stat st {};
  if (gid != static_cast<gid_t>(-1) && (lstat(path.c_str(), &st) != 0 || st.st_gid != gid) &&
      ::chown(path.c_str(), static_cast<uid_t>(-1), gid) != 0) {
    const std::error_code e{errno, std::system_category()};
    stop();
    return e;
  }
  if (::chmod(path.c_str(), static_cast<mode_t>(impl.config.mode & 07777)) != 0) {
    const std::error_code e{errno, std::system_category()};
    stop();
    return e;
  }
  impl.acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    stop();
    return {ec.value(), std::system_category()};
  }
  impl.listening = true;
  impl.accept();
  return {};
}

void Server::stop() {
  auto& impl = *impl_;
  const bool was_open = impl.acceptor.is_open();
  impl.listening = false;
  impl.accept_retry.cancel();
  boost::system::error_code ignored;
  impl.acceptor.close(ignored);
  auto sessions = impl.sessions;  // close() erases
  for (const auto& s : sessions) s->close();
  impl.sessions.clear();
  if (was_open) ::unlink(impl.config.path.c_str());
}

std::size_t Server::client_count() const noexcept {
  return impl_->sessions.size();
}
const std::string& Server::path() const noexcept {
  return impl_->config.path;
}

}  // namespace ds1928::control
