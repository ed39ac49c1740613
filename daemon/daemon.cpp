#include "daemon.hpp"

#include <spdlog/spdlog.h>

#include <boost/asio/post.hpp>
#include <chrono>
#include <cstdio>

#include "config/config_loader.hpp"
#include "sim/simulated_bus.hpp"

namespace ds1928 {

namespace {

[[nodiscard]] double us(int64_t ns) noexcept { return static_cast<double>(ns) / 1000.0; }

[[nodiscard]] nlohmann::json histogram_json(const HistogramSummary& h) {
  return {{"count", h.count},           {"min_us", us(h.min_ns)}, {"mean_us", us(h.mean_ns)},
          {"p50_us", us(h.p50_ns)},     {"p99_us", us(h.p99_ns)}, {"p999_us", us(h.p999_ns)},
          {"max_us", us(h.max_ns)},     {"overflow", h.overflow}};
}

}  // namespace

std::unique_ptr<BusDriver> make_bus(const DaemonConfig& config, std::string& why_not) {
  switch (config.bus) {
    case BusKind::Simulated: return std::make_unique<sim::SimulatedBus>(config);
    case BusKind::Powerlink:
      why_not = "the powerlink bus is not available in this build";
      return nullptr;
    case BusKind::Canio:
      why_not = "the canio bus is not available in this build";
      return nullptr;
  }
  why_not = "unknown bus";
  return nullptr;
}

struct Daemon::Services {};

Daemon::Daemon(DaemonConfig config)
    : config_(std::move(config)), signals_(io_, SIGINT, SIGTERM), timer_(io_) {}

Daemon::~Daemon() { stop(); }

std::error_code Daemon::start() {
  std::string why_not;
  bus_ = make_bus(config_, why_not);
  if (!bus_) {
    spdlog::error("{}", why_not);
    return std::make_error_code(std::errc::not_supported);
  }
  if (auto ec = CycleEngine::validate(config_.cycle)) {
    spdlog::error("cycle configuration: {}", ec.message());
    return ec;
  }
  if (auto ec = publisher_.open(config_.shm, static_cast<uint32_t>(config_.axes.size()),
                                uint64_t{config_.cycle.period_us} * 1000)) {
    spdlog::error("shared memory {}: {}", config_.shm.name, ec.message());
    return ec;
  }
  if (auto ec = bus_->start()) {
    spdlog::error("{} bus: {}", bus_->name(), ec.message());
    return ec;
  }
  work_ = std::make_unique<CycleWork>(config_, *bus_, publisher_);
  engine_ = std::make_unique<CycleEngine>(config_.cycle, *work_);
  auto started = engine_->start();
  if (!started) {
    spdlog::error("cycle engine: {}", started.error.message());
    return started.error;
  }
  if (!started.warning.empty()) spdlog::warn("{}", started.warning);
  spdlog::info("ds1928d cycling: bus {}, {} axis(es), period {} µs, {}", bus_->name(),
               config_.axes.size(), config_.cycle.period_us, engine_->rt_status_text());
  return {};
}

void Daemon::stop() noexcept {
  if (engine_) engine_->stop();
  if (bus_) bus_->stop();
  publisher_.close();
}

int Daemon::run() {
  if (auto ec = start()) {
    stop();
    return 1;
  }
  signals_.async_wait([this](const boost::system::error_code& ec, int signo) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signo);
    timer_.cancel();
    io_.stop();
  });
  timer_.expires_after(std::chrono::seconds(1));
  timer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec) on_second();
  });
  io_.run();
  stop();
  spdlog::info("ds1928d stopped");
  return 0;
}

void Daemon::on_second() {
  poll_register_results();
  spdlog::info("{}", summary_line());
  last_cycle_count_ = engine_->cycle_count();
  timer_.expires_after(std::chrono::seconds(1));
  timer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec) on_second();
  });
}

void Daemon::poll_register_results() {
  RegisterResult r;
  while (bus_->poll(r)) {
  }
}

std::string Daemon::summary_line() const {
  const auto s = engine_->stats_snapshot();
  std::string line = fmt::format("cycle {} | late p99 {:.1f} µs max {:.1f} µs | overruns {} | bus {}",
                                 engine_->cycle_count(), us(s.wake_latency.p99_ns),
                                 us(s.wake_latency.max_ns), s.overruns, to_string(bus_->state()));
  if (work_->axis_count() > 0) {
    ds1928_axis_data d{};
    (void)d;
  }
  return line;
}

nlohmann::json Daemon::stats_json() const {
  const auto s = engine_->stats_snapshot();
  return {{"cycles", s.cycles},
          {"overruns", s.overruns},
          {"skipped_cycles", s.skipped_cycles},
          {"reset_generation", s.reset_generation},
          {"wake_latency", histogram_json(s.wake_latency)},
          {"work", histogram_json(s.work)},
          {"exchanges", work_->exchanges()},
          {"frames_lost", work_->frames_lost()}};
}

nlohmann::json Daemon::axes_json() const {
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t i = 0; i < config_.axes.size(); ++i) {
    const AxisConfig& a = config_.axes[i];
    axes.push_back({{"index", i},
                    {"name", a.name},
                    {"node", a.node},
                    {"slot", a.slot},
                    {"function_model", static_cast<int>(a.function_model)}});
  }
  return axes;
}

nlohmann::json Daemon::status_json() const {
  nlohmann::json j;
  j["daemon"] = {{"version", "0.1.0"},
                 {"realtime", engine_->realtime()},
                 {"rt_status", engine_->rt_status_text()},
                 {"cycle_period_us", config_.cycle.period_us},
                 {"cycles", engine_->cycle_count()}};
  j["bus"] = {{"kind", std::string(bus_->name())}, {"state", std::string(to_string(bus_->state()))}};
  j["stats"] = stats_json();
  return j;
}

}  // namespace ds1928
