// The daemon's wiring: configuration → bus → cycle engine → shared memory, control socket,
// systemd. Owns every part; the normal thread runs Boost.Asio, the cycle thread the CycleWork.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "config/config.hpp"
#include "core/bus.hpp"
#include "core/cycle_engine.hpp"
#include "cycle_work.hpp"
#include "shm/publisher.hpp"

namespace ds1928 {

class Daemon {
 public:
  explicit Daemon(DaemonConfig config);
  ~Daemon();

  // Runs until SIGINT/SIGTERM. Returns the process exit code.
  int run();

  // Views for the control commands.
  [[nodiscard]] nlohmann::json status_json() const;
  [[nodiscard]] nlohmann::json axes_json() const;
  [[nodiscard]] nlohmann::json stats_json() const;
  [[nodiscard]] const DaemonConfig& config() const noexcept { return config_; }
  [[nodiscard]] CycleWork& cycle_work() noexcept { return *work_; }
  [[nodiscard]] CycleEngine& engine() noexcept { return *engine_; }
  [[nodiscard]] BusDriver& bus() noexcept { return *bus_; }
  [[nodiscard]] boost::asio::io_context& io() noexcept { return io_; }

 private:
  [[nodiscard]] std::error_code start();
  void stop() noexcept;
  void on_second();
  void poll_register_results();
  [[nodiscard]] std::string summary_line() const;

  DaemonConfig config_;
  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer timer_;
  std::unique_ptr<BusDriver> bus_;
  shm::Publisher publisher_;
  std::unique_ptr<CycleWork> work_;
  std::unique_ptr<CycleEngine> engine_;
  struct Services;
  std::unique_ptr<Services> services_;  // control socket, systemd notifier, EnDat service
  uint64_t last_cycle_count_ = 0;
  bool ready_sent_ = false;
  uint32_t next_tag_ = 1;
};

[[nodiscard]] std::unique_ptr<BusDriver> make_bus(const DaemonConfig& config, std::string& why_not);

}  // namespace ds1928
