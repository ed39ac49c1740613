// sd_notify for the daemon: READY=1, STATUS=, WATCHDOG=1 and STOPPING=1. Every call is a no-op
// when the daemon was not started by systemd (no NOTIFY_SOCKET). Normal thread only: each
// notification is a datagram send.
//
//   SystemdNotifier notifier;
//   notifier.supervise(io, [&] { return engine.cycle_count(); }, [&] { return status_line(); });
//   ...after the first cycle that exchanged data: notifier.ready("running");
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

namespace boost::asio {
class io_context;
}

namespace ds1928::control {

class SystemdNotifier {
 public:
  SystemdNotifier();
  ~SystemdNotifier();  // STOPPING=1 if READY=1 was sent; stops the timers
  SystemdNotifier(const SystemdNotifier&) = delete;
  SystemdNotifier& operator=(const SystemdNotifier&) = delete;

  // NOTIFY_SOCKET is set: systemd (Type=notify) listens.
  [[nodiscard]] bool active() const noexcept { return active_; }
  // WatchdogSec= of the unit (sd_watchdog_enabled), if the watchdog is on for this process.
  [[nodiscard]] std::optional<std::chrono::microseconds> watchdog_interval() const noexcept {
    return watchdog_;
  }

  void ready(std::string_view status = {});
  void status(std::string_view line);
  void stopping();

  // WATCHDOG=1, but only if `cycle_count` advanced since the previous ping (or this is the
  // first): a stalled cycle thread must let the watchdog fire. Returns whether it pinged.
  bool watchdog_tick(uint64_t cycle_count);

  // Timers on `io` (which the daemon runs on its normal thread): STATUS=<status_line()> every
  // `status_period` when it changed, and watchdog_tick(cycle_count()) at half the watchdog
  // interval. Stopped by the destructor or stop_supervising().
  void supervise(boost::asio::io_context& io, std::function<uint64_t()> cycle_count,
                 std::function<std::string()> status_line,
                 std::chrono::milliseconds status_period = std::chrono::seconds(1));
  void stop_supervising();

  // Notifications actually sent (for tests).
  [[nodiscard]] uint64_t watchdog_pings() const noexcept { return pings_; }

  struct Timers;

 private:
  void send(const std::string& message);

  bool active_ = false;
  bool ready_sent_ = false;
  std::optional<std::chrono::microseconds> watchdog_;
  std::optional<uint64_t> last_count_;
  uint64_t pings_ = 0;
  std::string last_status_;
  std::shared_ptr<Timers> timers_;
};

}  // namespace ds1928::control
