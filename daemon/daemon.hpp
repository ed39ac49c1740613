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

#include "bus_service.hpp"
#include "capture_service.hpp"
#include "config/config.hpp"
#include "control/control_server.hpp"
#include "core/bus.hpp"
#include "core/cycle_engine.hpp"
#include "cycle_work.hpp"
#include "endat_service.hpp"
#include "incident_service.hpp"
#include "metrics/http_server.hpp"
#include "module_errors.hpp"
#include "register_client.hpp"
#include "service/systemd_notifier.hpp"
#include "shm/publisher.hpp"
#include "topology.hpp"

namespace ds1928 {

// What changed on the bus since the last look, worded for the log: state transitions and what
// the bus kind adds (POWERLINK: nodes reset or booted by the MN, with the reason). Normal thread.
class BusWatch {
 public:
  [[nodiscard]] std::vector<BusEvent> poll(
      BusService& bus,
      std::chrono::steady_clock::time_point now = std::chrono::steady_clock::now());
  static constexpr std::chrono::seconds kRepeat = SaidCounter::kRepeat;

 private:
  bool seen_ = false;
  std::string state_;  // as reported (BusService::reported_state())
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
  [[nodiscard]] BusDriver& bus() noexcept { return bus_->driver(); }
  [[nodiscard]] BusService& bus_service() noexcept { return *bus_; }
  [[nodiscard]] boost::asio::io_context& io() noexcept { return io_; }
  [[nodiscard]] const std::string& socket_path() const noexcept { return socket_path_; }
  [[nodiscard]] IncidentService& incidents() noexcept { return *incidents_; }
  // The OpenMetrics text of GET /metrics (daemon_metrics.cpp); the bound address or "off".
  [[nodiscard]] std::string metrics_text(metrics::Format format) const;
  [[nodiscard]] std::string metrics_address() const;

 private:
  void register_commands();
  void on_tick();
  void start_metrics();
  [[nodiscard]] nlohmann::json axis_json(std::size_t axis, bool with_sample) const;

  DaemonConfig config_;
  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer tick_timer_;
  std::unique_ptr<BusService> bus_;
  std::unique_ptr<CaptureService> capture_;     // uses the bus' capture points: after bus_
  std::unique_ptr<IncidentService> incidents_;  // the flight recorder: idem
  shm::Publisher publisher_;
  std::unique_ptr<CycleWork> work_;
  std::unique_ptr<CycleEngine> engine_;
  std::unique_ptr<RegisterClient> registers_;
  std::unique_ptr<EnDatService> endat_;
  std::unique_ptr<Topology> topology_;  // the expected topology: after work_, before endat_ runs
  std::unique_ptr<control::Server> server_;
  std::unique_ptr<metrics::HttpServer> metrics_;
  control::SystemdNotifier notifier_;
  std::string socket_path_;
  std::chrono::steady_clock::time_point started_at_;
  std::chrono::steady_clock::time_point stats_reset_at_;
  std::chrono::steady_clock::time_point last_log_;
  ErrorJournal error_journal_{config_.axes.size()};
  BusWatch bus_watch_;
  bool metrics_failed_ = false;
  bool ready_sent_ = false;
  bool started_ = false;
};

// The incident a bus event is, if any (POWERLINK node reset/lost/threshold, CAN-I/O node silent;
// bus-off comes from the driver itself, core/incident.hpp).
[[nodiscard]] std::optional<IncidentKind> incident_of(const BusEvent& e);

// Logs a bus event with its journal fields (DS1928_BUS = `bus`).
void log_bus_event(const BusEvent& e, std::string_view bus);

// The bus' own socket commands, and "not_<kind>" answers for the other kinds' commands.
void register_bus_commands(control::Server& server, BusService& bus, const DaemonConfig& config);

}  // namespace ds1928
