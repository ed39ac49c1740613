#include "service/systemd_notifier.hpp"

#include <systemd/sd-daemon.h>

#include <cstdlib>

#include "control/asio.hpp"

namespace ds1928::control {

// Lives in the notifier; its timer handlers hold it weakly, so destroying it (on the io thread)
// ends the supervision.
struct SystemdNotifier::Timers : std::enable_shared_from_this<Timers> {
  Timers(boost::asio::io_context& io, SystemdNotifier& owner_)
      : owner(owner_), status(io), watchdog(io) {}

  void on_status() {
    const std::string line = status_line();
    if (line != owner.last_status_) owner.status(line);
    status.expires_after(status_period);
    status.async_wait([w = weak_from_this()](const boost::system::error_code& ec) {
      if (auto self = w.lock(); self && !ec) self->on_status();
    });
  }
  void on_watchdog() {
    owner.watchdog_tick(cycle_count());
    watchdog.expires_after(watchdog_period);
    watchdog.async_wait([w = weak_from_this()](const boost::system::error_code& ec) {
      if (auto self = w.lock(); self && !ec) self->on_watchdog();
    });
  }

  SystemdNotifier& owner;
  boost::asio::steady_timer status;
  boost::asio::steady_timer watchdog;
  std::function<uint64_t()> cycle_count;
  std::function<std::string()> status_line;
  std::chrono::steady_clock::duration status_period{};
  std::chrono::steady_clock::duration watchdog_period{};
};

SystemdNotifier::SystemdNotifier() {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  active_ = socket != nullptr && socket[0] != '\0';
  uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0 && usec > 0) watchdog_ = std::chrono::microseconds(usec);
}

SystemdNotifier::~SystemdNotifier() {
  stop_supervising();
  if (ready_sent_) stopping();
}

void SystemdNotifier::send(const std::string& message) {
  if (active_) sd_notify(0, message.c_str());
}

void SystemdNotifier::ready(std::string_view status) {
  ready_sent_ = true;
  std::string m = "READY=1";
  if (!status.empty()) {
    m += "\nSTATUS=";
    m += status;
    last_status_ = status;
  }
  send(m);
}

void SystemdNotifier::status(std::string_view line) {
  last_status_ = line;
  send("STATUS=" + std::string(line));
}

void SystemdNotifier::stopping() {
  send("STOPPING=1");
  ready_sent_ = false;
}

bool SystemdNotifier::watchdog_tick(uint64_t cycle_count) {
  if (last_count_ && *last_count_ == cycle_count) return false;
  last_count_ = cycle_count;
  ++pings_;
  send("WATCHDOG=1");
  return true;
}

void SystemdNotifier::supervise(boost::asio::io_context& io, std::function<uint64_t()> cycle_count,
                                std::function<std::string()> status_line,
                                std::chrono::milliseconds status_period) {
  stop_supervising();
  timers_ = std::make_shared<Timers>(io, *this);
  timers_->cycle_count = std::move(cycle_count);
  timers_->status_line = std::move(status_line);
  timers_->status_period = status_period;
  if (timers_->status_line) timers_->on_status();
  if (watchdog_ && timers_->cycle_count) {
    timers_->watchdog_period =
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(*watchdog_ / 2);
    timers_->on_watchdog();
  }
}

void SystemdNotifier::stop_supervising() {
  timers_.reset();
}

}  // namespace ds1928::control
