// The daemon's OpenMetrics endpoint: starting the HTTP server and the text of GET /metrics.
// Every figure is read on the normal thread from what the cycle thread already publishes
// (relaxed atomics, the statistics histograms, the buses' status snapshots); nothing here
// reaches into the cycle.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "daemon.hpp"
#include "module_leds.hpp"

namespace ds1928 {
namespace {

using metrics::Exposition;
using metrics::Type;

// Wake-up lateness and work buckets, ns: multiples of the statistics' 250 ns bins, within their
// 4.096 ms range (beyond it the overflow bin feeds +Inf).
constexpr std::array<int64_t, 11> kCycleBoundsNs{5'000,     10'000,    20'000,   50'000,
                                                 100'000,   200'000,   300'000,  500'000,
                                                 1'000'000, 2'000'000, 4'000'000};

// A Prometheus histogram from the engine's fine histogram: each 250 ns bin lies wholly below
// one bound (bounds are bin edges), so the buckets are exact: a bucket `le` counts the samples
// below its bound (a sample exactly on a bound counts in the next, a 250 ns distinction).
void cycle_histogram(Exposition& out, const LatencyHistogram& h) {
  constexpr std::size_t N = kCycleBoundsNs.size();
  std::array<uint64_t, N + 1> counts{};
  std::size_t b = 0;
  for (std::size_t i = 0; i < LatencyHistogram::kBins; ++i) {
    const int64_t lo = static_cast<int64_t>(i) * LatencyHistogram::kBinWidthNs;
    while (b < N && lo >= kCycleBoundsNs[b]) ++b;
    counts[b] += h.bin(i);
  }
  counts[N] += h.overflow();
  uint64_t total = 0;
  for (uint64_t c : counts) total += c;
  std::array<double, N> upper{};
  for (std::size_t i = 0; i < N; ++i) upper[i] = static_cast<double>(kCycleBoundsNs[i]) / 1e9;
  // The statistics keep the mean, not the sum, consistent with the bins: sum = mean × count.
  const double sum = static_cast<double>(h.summary().mean_ns) * static_cast<double>(total) / 1e9;
  out.histogram({}, upper, counts, sum);
}

std::string_view validity_label(std::size_t v) noexcept {
  static constexpr std::array<std::string_view, 4> kNames{"valid", "stale", "bus_down",
                                                          "module_error"};
  return v < kNames.size() ? kNames[v] : "unknown";
}

// The additional-information channels (axes[].info) as last published: one series per
// configured channel, labelled with its number and name. The age is left out until the
// channel's first valid read.
void append_info_metrics(Exposition& out, const DaemonConfig& config, CycleWork& work,
                         const std::vector<std::string>& index) {
  struct Row {
    std::size_t axis, channel;
  };
  std::vector<Row> rows;
  for (std::size_t i = 0; i < config.axes.size() && i < work.axis_count(); ++i)
    for (std::size_t n = 0; n < config.axes[i].info.size() && n < kInfoChannels; ++n)
      rows.push_back({i, n});
  if (rows.empty()) return;
  const auto each = [&](auto value) {
    for (const Row& r : rows) {
      const std::string channel = std::to_string(r.channel + 1);
      const AxisCounters& c = work.counters(r.axis);
      value({{"axis", index[r.axis]},
             {"name", config.axes[r.axis].name},
             {"channel", channel},
             {"info", config.axes[r.axis].info[r.channel].name}},
            c, r.channel);
    }
  };
  out.family("ds1928_axis_info_value", Type::Gauge,
             "Last value of the additional-information channel (EnDatInfo0N) read with its "
             "EnDatInfoOK bit set.");
  each([&](metrics::Labels l, const AxisCounters& c, std::size_t n) {
    out.sample(l, static_cast<double>(c.info_value[n].load(std::memory_order_relaxed)));
  });
  out.family("ds1928_axis_info_valid", Type::Gauge,
             "1 while the channel's last read had its EnDatInfoOK bit set.");
  each([&](metrics::Labels l, const AxisCounters& c, std::size_t n) {
    out.sample(l, uint64_t{(c.info_valid.load(std::memory_order_relaxed) >> n) & 1u});
  });
  out.family("ds1928_axis_info_age_seconds", Type::Gauge,
             "Time since the channel's value was read valid.", "seconds");
  const int64_t now = rt::now_ns();
  each([&](metrics::Labels l, const AxisCounters& c, std::size_t n) {
    const int64_t at = c.info_read_ns[n].load(std::memory_order_relaxed);
    if (at != 0) out.sample(l, static_cast<double>(std::max<int64_t>(0, now - at)) / 1e9);
  });
}

}  // namespace

void Daemon::start_metrics() {
  if (!config_.metrics.listen) return;
  const MetricsListen& l = *config_.metrics.listen;
  boost::system::error_code ec;
  const auto address = boost::asio::ip::make_address(l.address, ec);
  if (ec) {  // the configuration checked it already
    spdlog::warn("metrics endpoint {}: {}; running without it", l.address, ec.message());
    return;
  }
  metrics::HttpServerOptions o;
  o.endpoint = {address, l.port};
  o.max_connections = config_.metrics.max_connections;
  o.read_timeout = o.write_timeout = std::chrono::milliseconds(config_.metrics.timeout_ms);
  auto server = std::make_unique<metrics::HttpServer>(
      io_, o, [this](metrics::Format f) { return metrics_text(f); });
  // Observability must not stop the cycle: an address in use or not on this host is said, and
  // the daemon runs without the endpoint (status shows "metrics": "unavailable").
  if (auto e = server->start()) {
    // The hardened unit allows no IP unless its drop-in is installed: say so.
    const bool no_ip = e == std::errc::address_family_not_supported;
    spdlog::warn("metrics endpoint {}:{}: {}; running without it{}", l.address, l.port, e.message(),
                 no_ip ? " (IP sockets are not allowed here: install the unit's drop-in "
                         "ds1928d-metrics.conf, or set metrics.listen: off; docs/operations.md)"
                       : "");
    metrics_failed_ = true;
    return;
  }
  metrics_ = std::move(server);
}

std::string Daemon::metrics_address() const {
  if (metrics_) {
    const auto ep = metrics_->local_endpoint();
    return ep.address().is_v6() ? fmt::format("[{}]:{}", ep.address().to_string(), ep.port())
                                : fmt::format("{}:{}", ep.address().to_string(), ep.port());
  }
  return metrics_failed_ ? "unavailable" : "off";
}

std::string Daemon::metrics_text(metrics::Format format) const {
  Exposition out(format);
  const auto s = engine_->stats_snapshot();
  const std::string_view bus_name = bus_->driver().name();

  out.family("ds1928_build", Type::Info, "Version of ds1928d and the configured bus kind.");
  out.sample({{"version", PROJECT_VERSION}, {"bus", bus_name}}, uint64_t{1});

  out.family("ds1928_cycles", Type::Counter, "Cycles run by the cycle thread since the start.");
  out.sample(engine_->cycle_count());
  out.family("ds1928_cycle_overruns", Type::Counter,
             "Cycles whose work ran past the next cycle start (restarts on stats-reset).");
  out.sample(s.overruns);
  out.family("ds1928_cycle_skipped", Type::Counter,
             "Cycle slots left out to get back onto the timeline (restarts on stats-reset).");
  out.sample(s.skipped_cycles);
  out.family("ds1928_cycle_period_seconds", Type::Gauge, "Configured cycle period.", "seconds");
  out.sample({}, static_cast<double>(config_.cycle.period_us) / 1e6);
  out.family("ds1928_cycle_wakeup_lateness_seconds", Type::Histogram,
             "Cycle thread wake-up after the nominal cycle start (restarts on stats-reset).",
             "seconds");
  cycle_histogram(out, engine_->stats().wake_latency());
  out.family("ds1928_cycle_work_seconds", Type::Histogram,
             "Duration of one cycle's bus exchange and work (restarts on stats-reset).", "seconds");
  cycle_histogram(out, engine_->stats().work());
  out.family("ds1928_realtime", Type::Gauge,
             "1 when the cycle thread runs with SCHED_FIFO and locked memory.");
  out.sample(uint64_t{engine_->realtime() ? 1u : 0u});

  // The state `status` reports (the driver's, refined by the bus kind: "degraded", "no_nodes",
  // "waiting_for_link"), so that an alert and `ds1928ctl status` never disagree. Every state is
  // a series (0 or 1): a query for one state finds it whether it is current or not.
  out.family("ds1928_bus_state", Type::Gauge,
             "State of the bus as status reports it: 1 for the "
             "current state.");
  const std::string reported = bus_->reported_state().state;
  constexpr std::array<std::string_view, 8> kStates{
      "down",     "booting",  "operational",      "error",
      "degraded", "no_nodes", "waiting_for_link", "another_mn"};
  bool known = false;
  for (std::string_view st : kStates) {
    known = known || st == reported;
    out.sample({{"bus", bus_name}, {"state", st}}, uint64_t{st == reported ? 1u : 0u});
  }
  if (!known) out.sample({{"bus", bus_name}, {"state", reported}}, uint64_t{1});
  out.family("ds1928_bus_frames_lost", Type::Counter,
             "Expected responses (PRes, CAN-I/O inputs) that did not arrive within their cycle.");
  out.sample({{"bus", bus_name}}, work_->frames_lost());

  bus_->append_metrics(out);
  incidents_->append_metrics(out);
  if (topology_) topology_->append_metrics(out);
  append_module_metrics(out, *bus_, *work_, config_);

  // Per axis: what was published to shared memory, and the EnDat commands through Flatstream.
  const std::size_t axes = config_.axes.size();
  std::vector<std::string> index(axes);
  for (std::size_t i = 0; i < axes; ++i) index[i] = std::to_string(i);
  out.family("ds1928_axis_publications", Type::Counter,
             "Cycles published to shared memory per axis, by the validity published.");
  for (std::size_t i = 0; i < axes; ++i) {
    const AxisCounters& c = work_->counters(i);
    for (std::size_t v = 0; v < c.published.size(); ++v)
      out.sample(
          {{"axis", index[i]}, {"name", config_.axes[i].name}, {"validity", validity_label(v)}},
          c.published[v].load(std::memory_order_relaxed));
  }
  // The current state, one series per state (enum style: 1 for the current one), so that an
  // alert needs no rate: `ds1928_axis_state{state="valid"} == 0`.
  out.family("ds1928_axis_state", Type::Gauge,
             "State of each axis as published now: 1 for the current state.");
  for (std::size_t i = 0; i < axes; ++i) {
    const std::size_t now = work_->counters(i).validity.load(std::memory_order_relaxed);
    for (std::size_t v = 0; v < work_->counters(i).published.size(); ++v)
      out.sample({{"axis", index[i]}, {"name", config_.axes[i].name}, {"state", validity_label(v)}},
                 uint64_t{v == now ? 1u : 0u});
  }
  out.family("ds1928_axis_format_violations", Type::Counter,
             "Fresh positions whose fraction broke the format (published as module error).");
  for (std::size_t i = 0; i < axes; ++i)
    out.sample({{"axis", index[i]}, {"name", config_.axes[i].name}},
               work_->counters(i).format_violations.load(std::memory_order_relaxed));
  out.family("ds1928_axis_old_stamps", Type::Counter,
             "New positions stamped too long before their cycle: a late answer to an earlier "
             "cycle's request, published as stale.");
  for (std::size_t i = 0; i < axes; ++i)
    out.sample({{"axis", index[i]}, {"name", config_.axes[i].name}},
               work_->counters(i).old_stamps.load(std::memory_order_relaxed));
  out.family("ds1928_axis_stalled", Type::Counter,
             "Samples that repeated the last position (PosCycle, or PosTime, unchanged) beyond "
             "the stall limit: the acquisition stalled, published as stale.");
  for (std::size_t i = 0; i < axes; ++i)
    out.sample({{"axis", index[i]}, {"name", config_.axes[i].name}},
               work_->counters(i).stalled.load(std::memory_order_relaxed));
  append_module_error_metrics(out, config_, *work_);
  append_info_metrics(out, config_, *work_, index);
  if (endat_) {
    std::vector<EnDatService::Counters> ec(axes);
    for (std::size_t i = 0; i < axes; ++i) ec[i] = endat_->counters(i);
    const auto per_axis = [&](std::string_view name, std::string_view help, auto field) {
      out.family(name, Type::Counter, help);
      for (std::size_t i = 0; i < axes; ++i)
        out.sample({{"axis", index[i]}, {"name", config_.axes[i].name}}, ec[i].*field);
    };
    per_axis("ds1928_endat_commands", "EnDat commands sent to the module (resends included).",
             &EnDatService::Counters::commands_sent);
    per_axis("ds1928_endat_replies", "EnDat replies matched to the command in flight.",
             &EnDatService::Counters::replies);
    per_axis("ds1928_endat_timeouts", "EnDat commands without a reply before their deadline.",
             &EnDatService::Counters::timeouts);
    per_axis("ds1928_endat_resends", "EnDat commands sent again (not delivered by Flatstream).",
             &EnDatService::Counters::resends);
    out.family("ds1928_endat_jobs", Type::Counter,
               "EnDat jobs (socket commands, identification) by outcome.");
    for (std::size_t i = 0; i < axes; ++i) {
      const std::string_view n = config_.axes[i].name;
      out.sample({{"axis", index[i]}, {"name", n}, {"result", "done"}}, ec[i].jobs_done);
      out.sample({{"axis", index[i]}, {"name", n}, {"result", "failed"}}, ec[i].jobs_failed);
      out.sample({{"axis", index[i]}, {"name", n}, {"result", "cancelled"}}, ec[i].jobs_cancelled);
    }
    out.family("ds1928_endat_command_latency_seconds", Type::Histogram,
               "EnDat command from its first submission to the matching reply.", "seconds");
    for (std::size_t i = 0; i < axes; ++i) {
      const auto& h = endat_->command_latency(i);
      constexpr std::size_t N = EnDatService::LatencyHistogram::N;
      std::array<double, N> upper{};
      std::array<uint64_t, N + 1> counts{};
      for (std::size_t k = 0; k < N; ++k) upper[k] = static_cast<double>(h.upper_ns()[k]) / 1e9;
      for (std::size_t k = 0; k <= N; ++k) counts[k] = h.bucket(k);
      out.histogram({{"axis", index[i]}, {"name", config_.axes[i].name}}, upper, counts,
                    static_cast<double>(h.sum_ns()) / 1e9);
    }
  }

  out.family("ds1928_socket_clients", Type::Gauge, "Clients connected to the control socket.");
  out.sample(static_cast<uint64_t>(server_ ? server_->client_count() : 0));
  if (metrics_) {
    const auto& h = metrics_->counters();
    out.family("ds1928_http_connections", Type::Counter,
               "Connections to this endpoint: served, or refused over the connection limit.");
    out.sample({{"result", "served"}}, h.accepted - h.refused);
    out.sample({{"result", "refused"}}, h.refused);
    out.family(
        "ds1928_http_connections_peak", Type::Gauge,
        "Most connections this endpoint held open at once (limit: metrics.max_connections).");
    out.sample(h.peak_open);
    out.family("ds1928_http_responses", Type::Counter, "Responses of this endpoint by class.");
    out.sample({{"class", "2xx"}}, h.responses_ok);
    out.sample({{"class", "error"}}, h.responses_error);
    out.family("ds1928_http_timeouts", Type::Counter,
               "Connections cut because the request or the response did not complete in time.");
    out.sample({{"stage", "read"}}, h.read_timeouts);
    out.sample({{"stage", "write"}}, h.write_timeouts);
  }
  return out.finish();
}

}  // namespace ds1928
