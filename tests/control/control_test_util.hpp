// A control server on its own io_context thread, and a blocking line client, for the tests.
#pragma once

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <future>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>

#include "control/asio.hpp"
#include "control/control_server.hpp"
#include "support/wait.hpp"

namespace ds1928::control::test {

inline std::string temp_socket_path(const char* what) {
  static int serial = 0;
  const auto dir = std::filesystem::temp_directory_path() /
                   ("ds1928-ctl-" + std::to_string(getpid()) + "-" + std::to_string(++serial));
  return (dir / (std::string(what) + ".sock")).string();
}

class ServerThread {
 public:
  explicit ServerThread(SocketConfig config) : server_(io_, std::move(config)) {}
  ~ServerThread() { stop(); }

  Server& server() { return server_; }
  boost::asio::io_context& io() { return io_; }

  std::error_code start() {
    auto ec = server_.start();
    thread_ = std::thread([this] { io_.run(); });
    return ec;
  }
  void stop() {
    if (!thread_.joinable()) return;
    run([this] { server_.stop(); });
    work_.reset();
    io_.stop();
    thread_.join();
    std::filesystem::remove_all(std::filesystem::path(server_.path()).parent_path());
  }
  // Runs `f` on the server thread and waits for it.
  template <class F>
  std::invoke_result_t<F> run(F f) {
    std::packaged_task<decltype(f())()> task(std::move(f));
    auto result = task.get_future();
    boost::asio::post(io_, [&task] { task(); });
    return result.get();
  }
  std::size_t clients() {
    return run([this] { return server_.client_count(); });
  }
  // Waits until the client count reaches `n` (connections are closed asynchronously).
  bool wait_clients(std::size_t n) {
    return ds1928::test::wait_until([&] { return clients() == n; });
  }

 private:
  boost::asio::io_context io_;
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>> work_{
      boost::asio::make_work_guard(io_)};
  Server server_;
  std::thread thread_;
};

// Blocking client with a receive timeout, line-oriented.
class LineClient {
 public:
  explicit LineClient(const std::string& path, int timeout_ms = 3000) {
    fd_ = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
    if (connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }
  ~LineClient() { close(); }
  LineClient(const LineClient&) = delete;
  LineClient& operator=(const LineClient&) = delete;

  bool connected() const { return fd_ >= 0; }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  bool send_raw(const std::string& bytes) {
    std::size_t off = 0;
    while (off < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + off, bytes.size() - off, MSG_NOSIGNAL);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      off += static_cast<std::size_t>(n);
    }
    return true;
  }
  // The next line, or nullopt on EOF/timeout.
  std::optional<std::string> read_line() {
    for (;;) {
      const auto nl = buffer_.find('\n');
      if (nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return line;
      }
      char chunk[4096];
      const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
      // A process stopped and continued (a stalled machine, a debugger) sees EINTR here.
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return std::nullopt;
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }
  // True when the server closed the connection (EOF) within the timeout.
  bool at_eof() {
    char c;
    ssize_t n;
    do n = ::recv(fd_, &c, 1, 0);
    while (n < 0 && errno == EINTR);
    return buffer_.empty() && n == 0;
  }
  nlohmann::json request(const nlohmann::json& body) {
    send_raw(body.dump() + "\n");
    return reply();
  }
  nlohmann::json reply() {
    const auto line = read_line();
    if (!line) return nullptr;
    return nlohmann::json::parse(*line, nullptr, false);
  }

 private:
  int fd_ = -1;
  std::string buffer_;
};

inline std::string error_code_of(const nlohmann::json& reply) {
  if (!reply.is_object() || !reply.contains("error")) return "";
  return reply["error"].value("code", "");
}
inline std::string error_message_of(const nlohmann::json& reply) {
  if (!reply.is_object() || !reply.contains("error")) return "";
  return reply["error"].value("message", "");
}

}  // namespace ds1928::control::test
