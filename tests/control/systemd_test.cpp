// sd_notify through a notification socket the test owns, the watchdog gate, the log set-up.
#include <spdlog/async_logger.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "control/asio.hpp"
#include "service/logging.hpp"
#include "service/systemd_notifier.hpp"

using namespace ds1928::control;

namespace {

// Plays systemd's side: a datagram socket at NOTIFY_SOCKET, for the lifetime of the object.
class NotifySocket {
 public:
  NotifySocket() {
    path_ = (std::filesystem::temp_directory_path() /
             ("ds1928-notify-" + std::to_string(getpid()) + "-" + std::to_string(++serial_)))
                .string();
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path_.c_str(), sizeof(addr.sun_path) - 1);
    ::unlink(path_.c_str());
    REQUIRE(bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0);
    timeval tv{0, 200'000};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
    setenv("NOTIFY_SOCKET", path_.c_str(), 1);
  }
  ~NotifySocket() {
    unsetenv("NOTIFY_SOCKET");
    unsetenv("WATCHDOG_USEC");
    unsetenv("WATCHDOG_PID");
    ::close(fd_);
    ::unlink(path_.c_str());
  }
  // Every message received so far (non-blocking after the first timeout).
  std::vector<std::string> drain() {
    std::vector<std::string> out;
    char buf[1024];
    for (;;) {
      const ssize_t n = recv(fd_, buf, sizeof(buf), 0);
      if (n <= 0) break;
      out.emplace_back(buf, static_cast<std::size_t>(n));
    }
    return out;
  }

 private:
  static inline int serial_ = 0;
  std::string path_;
  int fd_ = -1;
};

}  // namespace

TEST_CASE("outside systemd every notification is a no-op") {
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  SystemdNotifier n;
  CHECK_FALSE(n.active());
  CHECK_FALSE(n.watchdog_interval());
  n.ready("running");
  n.status("x");
  CHECK(n.watchdog_tick(1));  // the gate still works; nothing is sent
}

TEST_CASE("READY, STATUS and STOPPING reach the notification socket") {
  NotifySocket systemd;
  {
    SystemdNotifier n;
    CHECK(n.active());
    n.ready("cycling at 1 kHz");
    n.status("2 axes valid");
    const auto got = systemd.drain();
    REQUIRE(got.size() == 2);
    CHECK(got[0] == "READY=1\nSTATUS=cycling at 1 kHz");
    CHECK(got[1] == "STATUS=2 axes valid");
  }
  const auto got = systemd.drain();
  REQUIRE(got.size() == 1);
  CHECK(got[0] == "STOPPING=1");
}

TEST_CASE("the watchdog is pinged only while the cycle counter advances") {
  NotifySocket systemd;
  setenv("WATCHDOG_USEC", "100000", 1);
  setenv("WATCHDOG_PID", std::to_string(getpid()).c_str(), 1);
  SystemdNotifier n;
  REQUIRE(n.watchdog_interval());
  CHECK(*n.watchdog_interval() == std::chrono::milliseconds(100));

  CHECK(n.watchdog_tick(10));
  CHECK_FALSE(n.watchdog_tick(10));
  CHECK(n.watchdog_tick(11));
  CHECK(systemd.drain() == std::vector<std::string>{"WATCHDOG=1", "WATCHDOG=1"});

  // Supervised: the counter runs for 300 ms, then stalls for 300 ms.
  boost::asio::io_context io;
  std::atomic<uint64_t> cycles{100};
  std::atomic<bool> stall{false};
  int status_calls = 0;
  n.supervise(
      io, [&] { return stall ? cycles.load() : cycles.fetch_add(1) + 1; },
      [&] {
        ++status_calls;
        return std::string("cycles ") + (stall ? "stalled" : "running");
      },
      std::chrono::milliseconds(50));
  boost::asio::steady_timer stop_at(io);
  stop_at.expires_after(std::chrono::milliseconds(300));
  stop_at.async_wait([&](auto) {
    stall = true;
    // One more ping may see the last advance; from then on nothing.
  });
  const uint64_t pings_before = n.watchdog_pings();
  io.run_for(std::chrono::milliseconds(330));
  const uint64_t pings_running = n.watchdog_pings() - pings_before;
  io.run_for(std::chrono::milliseconds(300));
  const uint64_t pings_stalled = n.watchdog_pings() - pings_before - pings_running;
  n.stop_supervising();
  // Every 50 ms while running: about 7 pings; at most one after the stall began.
  CHECK(pings_running >= 4);
  CHECK(pings_stalled <= 1);
  CHECK(status_calls >= 8);
  const auto got = systemd.drain();
  CHECK(std::count(got.begin(), got.end(), "STATUS=cycles running") == 1);  // only changes
  CHECK(std::count(got.begin(), got.end(), "STATUS=cycles stalled") == 1);
}

TEST_CASE("logging: sink detection, level names, asynchronous logger") {
  unsetenv("JOURNAL_STREAM");
  unsetenv("INVOCATION_ID");
  CHECK(detect_log_sink() == LogSink::Console);
  setenv("INVOCATION_ID", "0123456789abcdef", 1);
  CHECK(detect_log_sink() == LogSink::Journald);
  unsetenv("INVOCATION_ID");
  setenv("JOURNAL_STREAM", "8:12345", 1);
  CHECK(detect_log_sink() == LogSink::Journald);
  unsetenv("JOURNAL_STREAM");

  CHECK(parse_log_level("debug") == spdlog::level::debug);
  CHECK(parse_log_level("warning") == spdlog::level::warn);
  CHECK(parse_log_level("error") == spdlog::level::err);
  CHECK_FALSE(parse_log_level("loud"));

  auto logger = setup_logging(spdlog::level::off, LogSink::Console, "ds1928d-test");
  REQUIRE(logger);
  CHECK(std::dynamic_pointer_cast<spdlog::async_logger>(logger) != nullptr);
  CHECK(spdlog::default_logger() == logger);
  logger->set_level(spdlog::level::info);
  // Far more messages than the queue holds: callers never wait (oldest are dropped).
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 50'000; ++i) logger->debug("filtered {}", i);
  CHECK(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(2));
  shutdown_logging();
}
