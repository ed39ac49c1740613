// The daemon's wiring: configuration → bus → cycle engine → shared memory, control socket,
// systemd. Owns every part; the normal thread runs Boost.Asio, the cycle thread the CycleWork.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "control/control_server.hpp"
#include "control/systemd_notifier.hpp"
#include "core/bus.hpp"
#include "core/cycle_engine.hpp"
#include "cycle_work.hpp"
#include "endat_service.hpp"
#include "register_client.hpp"
#include "shm/publisher.hpp"

namespace ds1928 {

// What changed on the bus since the last look, worded for the log: state transitions and, on
// POWERLINK, nodes reset or booted by the MN (with the reason). Normal thread.
struct BusEvent {
  bool warning = false;
  std::string text;
};
class BusWatch {
 public:
  // Thresholds that only count (cycle time exceeded, late PRes) are said at most once per
  // `repeat` per source, with how often they fired meanwhile: a cycle that is too short for its
  // network must not flood the journal.
  [[nodiscard]] std::vector<BusEvent> poll(
      const BusDriver& bus,
      std::chrono::steady_clock::time_point now = std::chrono::steady_clock::now());
  static constexpr std::chrono::seconds kRepeat{1};

 private:
  // A counter whose increases are reported, rate-limited.
  struct Said {
    uint32_t said = 0;  // value when last reported
    std::chrono::steady_clock::time_point at{};
    // True (and `more` set) when `value` grew and the last report is old enough.
    bool due(uint32_t value, std::chrono::steady_clock::time_point now, uint32_t& more);
  };
  struct NodeSeen {
    uint32_t resets = 0;
    uint32_t boots = 0;
    uint32_t object_failures = 0;
    Said late_pres;
    Said nmt_refused;
  };
  bool seen_ = false;
  BusState state_ = BusState::Down;
  Said cycle_time_exceeded_;
  std::vector<NodeSeen> nodes_;
};

class Daemon {
 public:
  explicit Daemon(DaemonConfig config);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Starts everything; errors are logged and returned.
  [[nodiscard]] std::error_code start();
  // Runs the normal thread until SIGINT/SIGTERM or request_stop(). Returns the exit code.
  int run();
  // Any thread.
  void request_stop();
  void stop() noexcept;

  // Views for the control commands.
  [[nodiscard]] nlohmann::json status_json() const;
  [[nodiscard]] nlohmann::json axes_json() const;
  [[nodiscard]] nlohmann::json stats_json() const;
  [[nodiscard]] std::string summary_line() const;
  [[nodiscard]] const DaemonConfig& config() const noexcept { return config_; }
  [[nodiscard]] CycleWork& cycle_work() noexcept { return *work_; }
  [[nodiscard]] CycleEngine& engine() noexcept { return *engine_; }
  [[nodiscard]] BusDriver& bus() noexcept { return *bus_; }
  [[nodiscard]] boost::asio::io_context& io() noexcept { return io_; }
  [[nodiscard]] const std::string& socket_path() const noexcept { return socket_path_; }

 private:
  void register_commands();
  void on_tick();
  [[nodiscard]] nlohmann::json axis_json(std::size_t axis, bool with_sample) const;

  DaemonConfig config_;
  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer tick_timer_;
  std::unique_ptr<BusDriver> bus_;
  shm::Publisher publisher_;
  std::unique_ptr<CycleWork> work_;
  std::unique_ptr<CycleEngine> engine_;
  std::unique_ptr<RegisterClient> registers_;
  std::unique_ptr<EnDatService> endat_;
  std::unique_ptr<control::Server> server_;
  control::SystemdNotifier notifier_;
  std::string socket_path_;
  std::chrono::steady_clock::time_point started_at_;
  std::chrono::steady_clock::time_point stats_reset_at_;
  std::chrono::steady_clock::time_point last_log_;
  BusWatch bus_watch_;
  bool ready_sent_ = false;
  bool started_ = false;
};

[[nodiscard]] std::unique_ptr<BusDriver> make_bus(const DaemonConfig& config, std::string& why_not);
[[nodiscard]] nlohmann::json bus_status_json(const BusDriver& bus);

}  // namespace ds1928
