#include "daemon.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <boost/asio/post.hpp>
#include <csignal>
#include <cstdio>
#include <cstring>

#include "canio/canio_bus.hpp"
#include "config/config_loader.hpp"
#include "control/socket_path.hpp"
#include "endat_service.hpp"
#include "host_checks.hpp"
#include "module_leds.hpp"
#include "service/journal.hpp"
#include "shm/shm_error.hpp"

namespace ds1928 {

namespace {

using json = nlohmann::json;

[[nodiscard]] json quantiles_json(const HistogramSummary& h) {
  return {{"count", h.count}, {"min", h.min_ns},   {"mean", h.mean_ns}, {"p50", h.p50_ns},
          {"p99", h.p99_ns},  {"p999", h.p999_ns}, {"max", h.max_ns},   {"overflow", h.overflow}};
}

[[nodiscard]] std::string_view validity_name(uint8_t v) noexcept {
  switch (static_cast<shm::AxisValidity>(v)) {
    case shm::AxisValidity::Valid:
      return "valid";
    case shm::AxisValidity::Stale:
      return "stale";
    case shm::AxisValidity::BusDown:
      return "bus_down";
    case shm::AxisValidity::ModuleError:
      return "module_error";
  }
  return "?";
}

[[nodiscard]] double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

constexpr auto kTick = std::chrono::milliseconds(10);

}  // namespace

Daemon::Daemon(DaemonConfig config)
    : config_(std::move(config)), signals_(io_, SIGINT, SIGTERM, SIGHUP), tick_timer_(io_) {
  // A closed terminal (SIGHUP) or a closed pipe on the log's output (SIGPIPE, `ds1928d | head`)
  // would otherwise end the process at once, leaving the shared memory and the socket behind:
  // both stop the daemon as SIGTERM does. Sockets send with MSG_NOSIGNAL, so a client that went
  // away never raises SIGPIPE.
  signals_.add(SIGPIPE);
}

Daemon::~Daemon() {
  stop();
}

std::error_code Daemon::start() {
  started_at_ = stats_reset_at_ = last_log_ = std::chrono::steady_clock::now();
  if (auto ec = CycleEngine::validate(config_.cycle)) {
    spdlog::error("cycle configuration: {}", ec.message());
    return ec;
  }
  std::string why_not;
  bus_ = make_bus_service(config_, why_not);
  if (!bus_) {
    control::log_event(spdlog::level::err, {control::LogEvent::StartFailed, to_string(config_.bus)},
                       why_not);
    return std::make_error_code(std::errc::not_supported);
  }
  capture_ = std::make_unique<CaptureService>(io_, config_, bus_->capture_taps());
  incidents_ =
      std::make_unique<IncidentService>(config_, bus_->capture_taps(), std::string(bus().name()));
  incidents_->open();
  bus().set_incident_sink(&incidents_->sink());
  std::vector<shm::InfoNames> info_names(config_.axes.size());
  for (std::size_t a = 0; a < config_.axes.size(); ++a)
    for (std::size_t n = 0; n < config_.axes[a].info.size() && n < kInfoChannels; ++n)
      info_names[a][n] = config_.axes[a].info[n].name;
  if (auto ec = publisher_.open(config_.shm, static_cast<uint32_t>(config_.axes.size()),
                                uint64_t{config_.cycle.period_us} * 1000, info_names)) {
    spdlog::error("shared memory {}: {}", config_.shm.name,
                  ec == shm::ShmError::kUnknownGroup
                      ? "shm.group: " + group_missing(config_.shm.group)
                      : ec.message());
    return ec;
  }
  if (auto ec = bus().start()) {
    const std::string detail = bus_->start_detail();
    control::log_event(spdlog::level::err,
                       {control::LogEvent::StartFailed, bus().name(), -1, -1, ec.message()},
                       fmt::format("{} bus: {}{}", bus().name(), ec.message(),
                                   detail.empty() ? std::string() : ": " + detail));
    return ec;
  }

  // Control socket: the configured path, or the per-user fallback when its directory cannot be
  // made or written (a daemon started by hand without root). Something planted at the path or a
  // directory others control is refused outright: moving elsewhere would hide it.
  SocketConfig socket = config_.socket;
  if (!socket.group.empty())
    if (const std::string missing = group_missing(socket.group); !missing.empty()) {
      spdlog::error("control socket {}: socket.group: {}", socket.path, missing);
      return std::make_error_code(std::errc::invalid_argument);
    }
  server_ = std::make_unique<control::Server>(io_, socket);
  register_commands();
  if (auto ec = server_->start()) {
    if (!control::directory_unusable(ec)) {
      spdlog::error("control socket {}: {}", config_.socket.path, ec.message());
      return ec;
    }
    const std::string fallback = fallback_socket_path(config_.socket.path);
    spdlog::warn("control socket {}: {}; using {}", config_.socket.path, ec.message(), fallback);
    socket.path = fallback;
    server_ = std::make_unique<control::Server>(io_, socket);
    register_commands();
    if (auto ec2 = server_->start()) {
      spdlog::error("control socket {}: {}", fallback, ec2.message());
      return ec2;
    }
  }
  socket_path_ = socket.path;

  work_ = std::make_unique<CycleWork>(config_, bus(), publisher_);
  work_->set_incident_sink(&incidents_->sink());
  registers_ = std::make_unique<RegisterClient>(io_, bus());
  engine_ = std::make_unique<CycleEngine>(config_.cycle, *work_);
  auto started = engine_->start();
  if (!started) {
    spdlog::error("cycle engine: {}", started.error.message());
    return started.error;
  }
  started_ = true;
  if (!started.warning.empty()) spdlog::warn("{}", started.warning);
  // The shared-memory wake-up thread: one priority below the cycle thread, on its CPU, so that
  // it runs the moment the cycle thread has published and sleeps (docs/shared-memory.md).
  if (const int rc =
          publisher_.place_waker(std::max(config_.cycle.rt_priority - 1, 1), config_.cycle.cpu);
      rc != 0 && engine_->realtime())
    spdlog::warn("shared memory wake-up thread: scheduling not applied ({})", rt::errno_text(rc));
  registers_->start(std::chrono::microseconds(std::max<uint32_t>(config_.cycle.period_us, 1000)));
  endat_ = std::make_unique<EnDatService>(io_, *work_, *registers_, config_);
  topology_ = std::make_unique<Topology>(config_, *work_);
  endat_->set_identified_hook(
      [this](std::size_t axis, std::error_code ec, const endat::Identification* found) {
        topology_->on_identified(axis, ec, found);
      });
  endat_->set_cause_source([this](std::size_t axis) { return bus_->axis_cause(axis); });
  endat_->register_commands(*server_);
  endat_->start();
  notifier_.supervise(
      io_, [this] { return engine_->cycle_count(); }, [this] { return summary_line(); });
  start_metrics();
  if (const BusService::Reported r = bus_->reported_state(); r.state == "waiting_for_link")
    control::log_event(spdlog::level::warn,
                       {control::LogEvent::BusState, bus().name(), -1, -1, r.cause},
                       fmt::format("bus {}: waiting for the link: {}", bus().name(), r.cause));
  control::log_event(
      spdlog::level::info, {control::LogEvent::Started, bus().name()},
      fmt::format("ds1928d {} cycling: bus {}, {} axis(es), period {} µs; {}; shm {}; socket {}",
                  PROJECT_VERSION, bus().name(), config_.axes.size(), config_.cycle.period_us,
                  engine_->rt_status_text(), config_.shm.name, socket_path_));
  return {};
}

void Daemon::stop() noexcept {
  if (started_)
    control::log_event(spdlog::level::info, {control::LogEvent::Stopping, bus_ ? bus().name() : ""},
                       "ds1928d stopping");
  if (metrics_) metrics_->stop();
  notifier_.stop_supervising();
  if (started_) notifier_.stopping();
  publisher_.set_state(shm::DaemonState::Stopping);
  if (endat_) endat_->stop();
  if (engine_) engine_->stop();
  if (registers_) registers_->stop();
  if (capture_) capture_->abort();
  if (incidents_) incidents_->poll(0, true);  // the incidents still in their tail: written now
  if (server_) server_->stop();
  if (bus_) bus().stop();
  publisher_.close();
  started_ = false;
}

void Daemon::request_stop() {
  boost::asio::post(io_, [this] {
    tick_timer_.cancel();
    io_.stop();
  });
}

int Daemon::run() {
  if (auto ec = start()) {
    stop();
    return 1;
  }
  signals_.async_wait([this](const boost::system::error_code& ec, int signo) {
    if (ec) return;
    spdlog::info("signal {} (SIG{}) received: stopping", signo, sigabbrev_np(signo));
    tick_timer_.cancel();
    io_.stop();
  });
  tick_timer_.expires_after(kTick);
  tick_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec) on_tick();
  });
  // Handlers contain their own failures (the control server answers them); this is the net
  // under everything else posted to the loop: log it and keep serving, the cycle is not ours.
  for (;;) {
    try {
      io_.run();
      break;
    } catch (const std::exception& e) {
      spdlog::error("event loop: uncaught exception: {}; continuing", e.what());
    } catch (...) {
      spdlog::error("event loop: uncaught non-standard exception; continuing");
    }
  }
  stop();
  return 0;
}

void Daemon::on_tick() {
  // READY=1 once the first cycle exchanged data with the modules, or once the daemon waits for
  // a link that is down: it is up and says why nothing moves (STATUS=), and a cable plugged in
  // later must not find a unit systemd failed for its start timeout.
  if (!ready_sent_) {
    if (work_->data_exchanges() > 0) {
      ready_sent_ = true;
      notifier_.ready(summary_line());
      spdlog::info(
          "first data exchanged: ready (cycle 0, the start-up's one-time work, took {:.0f} "
          "µs; not counted as an overrun)",
          static_cast<double>(engine_->first_cycle_work_ns()) / 1000.0);
    } else if (const BusService::Reported r = bus_->reported_state();
               r.state == "waiting_for_link") {
      ready_sent_ = true;
      notifier_.ready(summary_line());
      spdlog::info("ready, waiting for the link");
    } else if (r.state == "another_mn") {
      // Up, but it will not cycle on this segment: said once, at error level, with the remedy.
      ready_sent_ = true;
      notifier_.ready(summary_line());
      control::log_event(spdlog::level::err,
                         {control::LogEvent::BusState, bus().name(), -1, -1, r.cause},
                         fmt::format("bus {}: {}", bus().name(), r.cause));
    }
  }
  for (const BusEvent& e : bus_watch_.poll(*bus_)) {
    log_bus_event(e, bus().name());
    if (const auto kind = incident_of(e)) incidents_->raise(*kind, e.node, e.axis, e.text);
  }
  incidents_->poll();
  error_journal_.poll(config_, *work_, bus().name());
  const auto now = std::chrono::steady_clock::now();
  if (now - last_log_ >= std::chrono::seconds(1)) {
    last_log_ = now;
    spdlog::info("{}", summary_line());
    // Free heap pages back to the kernel (they stay resident and locked under mlockall until
    // then): what a burst of clients left behind. The cycle thread never uses malloc, so the
    // arena locks this takes are never in its way.
    (void)rt::trim_heap(256 * 1024);
  }
  tick_timer_.expires_after(kTick);
  tick_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec) on_tick();
  });
}

std::string Daemon::summary_line() const {
  const auto s = engine_->stats_snapshot();
  const BusService::Reported bus = bus_->reported_state();
  std::string line = fmt::format(
      "cycle {} | late p99 {:.1f} µs max {:.1f} µs | overruns {} | {}{}", engine_->cycle_count(),
      s.wake_latency.p99_ns / 1000.0, s.wake_latency.max_ns / 1000.0, s.overruns,
      bus_->driver().name(),
      bus.state == "operational"
          ? std::string()
          : fmt::format(" {}{}", bus.state, bus.cause.empty() ? "" : " (" + bus.cause + ")"));
  if (!engine_->realtime()) line += " | NOT real-time";
  if (work_->axis_count() > 0) {
    const AxisCounters& c = work_->counters(0);
    const auto raw = c.position_raw.load(std::memory_order_relaxed);
    const double periods = static_cast<double>(static_cast<int64_t>(raw)) / 65536.0;
    line += fmt::format(" | {} {:.4f} periods ({})", config_.axes[0].name, periods,
                        validity_name(c.validity.load(std::memory_order_relaxed)));
  }
  return line;
}

json Daemon::axis_json(std::size_t i, bool with_sample) const {
  const AxisConfig& a = config_.axes[i];
  AxisCounters& c = work_->counters(i);
  json j{{"axis", i},
         {"name", a.name},
         {"state", validity_name(c.validity.load(std::memory_order_relaxed))},
         {"error_info", c.error_info.load(std::memory_order_relaxed)},
         {"endat_error", c.endat_error.load(std::memory_order_relaxed)},
         {"endat_warning", c.endat_warning.load(std::memory_order_relaxed)},
         {"errors", error_bits_json(error_words(c), a.error_policy())}};
  add_module_leds(j, module_leds(*bus_, *work_, config_, i));
  const auto identity = static_cast<IdentityState>(c.identity.load(std::memory_order_relaxed));
  if (identity != IdentityState::Unchecked) {
    j["identity"] = std::string(to_string(identity));
    if (topology_)
      if (const std::string why = topology_->reason(i); !why.empty()) j["identity_reason"] = why;
  }
  if (!with_sample) return j;
  const uint64_t raw = c.position_raw.load(std::memory_order_relaxed);
  j["node"] = a.node;
  j["slot"] = a.slot;
  j["function_model"] = static_cast<int>(a.function_model);
  j["position_raw"] = raw;
  j["periods"] = a.module.position_signed ? (static_cast<int64_t>(raw) >> 16)
                                          : static_cast<int64_t>(raw >> 16);
  j["fraction"] = raw & 0xFFFF;
  j["position_sdc"] = static_cast<int32_t>(static_cast<uint32_t>(raw));
  j["pos_cycle"] = c.pos_cycle.load(std::memory_order_relaxed);
  j["pos_time_ns"] = c.pos_time_ns.load(std::memory_order_relaxed);
  switch (static_cast<TimeSource>(c.time_source.load(std::memory_order_relaxed))) {
    case TimeSource::None:
      j["time_source"] = "none";
      break;
    case TimeSource::NetTime:
      j["time_source"] = "nettime";
      break;
    case TimeSource::RxTimestamp:
      j["time_source"] = "rx_timestamp";
      break;
  }
  j["cycle"] = c.cycle.load(std::memory_order_relaxed);
  j["fresh_cycles"] = c.fresh_cycles.load(std::memory_order_relaxed);
  j["stale_cycles"] = c.stale_cycles.load(std::memory_order_relaxed);
  j["new_positions"] = c.new_positions.load(std::memory_order_relaxed);
  j["format_violations"] = c.format_violations.load(std::memory_order_relaxed);
  j["old_stamps"] = c.old_stamps.load(std::memory_order_relaxed);
  j["repeats"] = c.repeats.load(std::memory_order_relaxed);
  j["stalled"] = c.stalled.load(std::memory_order_relaxed);
  j["held"] = c.held.load(std::memory_order_relaxed);
  const TunnelCounters& t = work_->tunnel_counters(i);
  j["flatstream"] = {{"messages_sent", t.messages_sent.load(std::memory_order_relaxed)},
                     {"messages_failed", t.messages_failed.load(std::memory_order_relaxed)},
                     {"messages_received", t.messages_received.load(std::memory_order_relaxed)},
                     {"sequences_repeated", t.sequences_repeated.load(std::memory_order_relaxed)},
                     {"resyncs", t.resyncs.load(std::memory_order_relaxed)},
                     {"events_dropped", t.events_dropped.load(std::memory_order_relaxed)},
                     {"output", flatstream::to_string(static_cast<flatstream::SenderState>(
                                    t.output_state.load(std::memory_order_relaxed)))},
                     {"input", flatstream::to_string(static_cast<flatstream::ReceiverState>(
                                   t.input_state.load(std::memory_order_relaxed)))}};
  return j;
}

json Daemon::axes_json() const {
  json axes = json::array();
  for (std::size_t i = 0; i < config_.axes.size(); ++i) axes.push_back(axis_json(i, true));
  return {{"axes", std::move(axes)}};
}

json Daemon::stats_json() const {
  const auto s = engine_->stats_snapshot();
  json bus = bus_->status_json();
  bus["frames_lost"] = work_->frames_lost();
  bus["exchanges"] = work_->exchanges();
  return {{"since_reset_s", seconds_since(stats_reset_at_)},
          {"cycle",
           {{"period_us", config_.cycle.period_us},
            {"count", s.cycles},
            {"overruns", s.overruns},
            {"skipped", s.skipped_cycles},
            {"first_cycle_work_ns", engine_->first_cycle_work_ns()},
            {"reset_generation", s.reset_generation},
            {"wake_latency_ns", quantiles_json(s.wake_latency)},
            {"work_ns", quantiles_json(s.work)}}},
          {"bus", std::move(bus)}};
}

json Daemon::status_json() const {
  const auto s = engine_->stats_snapshot();
  json axes = json::array();
  for (std::size_t i = 0; i < config_.axes.size(); ++i) {
    axes.push_back(axis_json(i, false));
    axes.back()["endat"] = endat_ ? endat_->status_json(i) : json();
  }
  return {{"daemon",
           {{"version", PROJECT_VERSION},
            {"pid", static_cast<int64_t>(::getpid())},
            {"state", engine_->running() ? "running" : "stopped"},
            {"uptime_s", seconds_since(started_at_)},
            {"realtime", engine_->realtime()},
            {"rt_status", engine_->rt_status_text()},
            {"socket", socket_path_},
            {"metrics", metrics_address()}}},
          {"shm", {{"name", config_.shm.name}, {"generation", publisher_.generation()}}},
          {"bus", bus_->status_json()},
          {"capture", capture_->status_json()},
          {"flight_recorder", incidents_->status_json()},
          {"cycle",
           {{"period_us", config_.cycle.period_us},
            {"count", engine_->cycle_count()},
            {"overruns", s.overruns},
            {"skipped", s.skipped_cycles},
            {"first_cycle_work_ns", engine_->first_cycle_work_ns()},
            {"wake_latency_ns", quantiles_json(s.wake_latency)}}},
          {"axes", std::move(axes)}};
}

void Daemon::register_commands() {
  using control::Reply;
  using control::Request;
  server_->add_command("status", [this](const Request&, Reply reply) { reply.ok(status_json()); });
  register_bus_commands(*server_, *bus_, config_);
  capture_->register_commands(*server_);
  incidents_->register_commands(*server_);
  server_->add_command("topology", [this](const Request&, Reply reply) {
    if (!topology_) return reply.error("starting", "the daemon is still starting");
    json t = topology_->topology_json(endat_.get(), bus_->status_json());
    for (std::size_t i = 0; i < config_.axes.size() && i < t["axes"].size(); ++i)
      add_module_leds(t["axes"][i], module_leds(*bus_, *work_, config_, i));
    reply.ok(std::move(t));
  });
  server_->add_command("axes", [this](const Request&, Reply reply) { reply.ok(axes_json()); });
  server_->add_command("stats", [this](const Request&, Reply reply) { reply.ok(stats_json()); });
  server_->add_command("stats-reset", [this](const Request&, Reply reply) {
    engine_->request_stats_reset();
    stats_reset_at_ = std::chrono::steady_clock::now();
    reply.ok();
  });
  server_->add_command("ack-errors", [this](const Request& req, Reply reply) {
    const uint64_t axis = req.get_uint("axis", 0xFFFF);
    const uint64_t bits = req.get_uint("bits", 0xFF);
    if (axis >= config_.axes.size()) {
      reply.error(control::ErrorCode::BadArgument,
                  fmt::format("axis: {} does not exist (0..{})", axis, config_.axes.size() - 1));
      return;
    }
    // Clearing a module error hides it from every other client: a reader may not.
    if (!control::peer_is_privileged(req.peer(), config_.socket.privileged_group)) {
      reply.error("permission_denied", "'ack-errors' clears module errors: needs uid 0 or group '" +
                                           config_.socket.privileged_group + "'");
      return;
    }
    if (bus().state() != BusState::Operational) {
      reply.error("bus_down", fmt::format("the {} bus is {}: nothing to acknowledge to",
                                          bus().name(), to_string(bus().state())));
      return;
    }
    if (!work_->post({AxisCommand::Kind::AckErrors, static_cast<uint16_t>(axis),
                      static_cast<uint8_t>(bits)})) {
      reply.error("busy", "the cycle thread's command queue is full; try again");
      return;
    }
    reply.ok({{"axis", axis}, {"bits", bits}});
  });
}

std::optional<IncidentKind> incident_of(const BusEvent& e) {
  switch (e.event) {
    case control::LogEvent::NodeReset:
      // A CAN-I/O node's boot-up message: it restarted by itself (canio_service.cpp).
      if (e.reason == canio::to_string(canio::CanioNodeEventKind::BootUp))
        return IncidentKind::NodeBootUp;
      // The MN's reasons (powerlink/errors.cpp): a CN dropping out of its state is "lost".
      if (e.reason.find("loss of PRes threshold") != std::string::npos)
        return IncidentKind::PresThreshold;
      if (e.reason.find("not operational") != std::string::npos) return IncidentKind::NodeLost;
      return IncidentKind::NodeReset;
    case control::LogEvent::NodeSilent:
      if (e.reason == canio::to_string(canio::CanioNodeEventKind::HeartbeatMissed))
        return IncidentKind::HeartbeatMissed;
      // NMT Start sent again to a node that stayed silent after it: logged and counted, but it
      // repeats with back-off while the node stays so; the node's loss was the incident.
      if (e.reason == canio::to_string(canio::CanioNodeEventKind::StartRetry)) return std::nullopt;
      return IncidentKind::NodeLost;
    default:
      return std::nullopt;
  }
}

}  // namespace ds1928
