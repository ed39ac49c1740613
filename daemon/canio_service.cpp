#include "canio_service.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "can/socketcan_port.hpp"
#include "canio/module_phase.hpp"
#include "capture/capturing_can_port.hpp"

namespace ds1928 {

using canio::CanioBus;

namespace {

std::string hex32(uint32_t v) {
  return fmt::format("0x{:08X}", v);
}

// A node's expected identity next to what its last check found (`status`, `topology`).
nlohmann::json identity_json(const canio::NodeIdentity& id) {
  nlohmann::json expected = nlohmann::json::object();
  nlohmann::json found = nlohmann::json::object();
  for (std::size_t f = 0; f < canio::kIdentityFields.size(); ++f) {
    const std::string key(canio::kIdentityFields[f].key);
    const unsigned bit = 1U << f;
    expected[key] = (id.expected_mask & bit) ? nlohmann::json(hex32(id.expected[f])) : nullptr;
    found[key] = (id.read_mask & bit)         ? nlohmann::json(hex32(id.found[f]))
                 : (id.unreadable_mask & bit) ? nlohmann::json("unreadable")
                                              : nullptr;
  }
  const std::string difference = canio::describe_identity(id);
  return {{"state", std::string(canio::to_string(id.state))},
          {"expected", std::move(expected)},
          {"found", id.read_mask | id.unreadable_mask ? std::move(found) : nlohmann::json(nullptr)},
          {"difference", difference.empty() ? nlohmann::json(nullptr) : nlohmann::json(difference)},
          {"checks", id.checks},
          {"mismatches", id.mismatches}};
}

// The driver's index of CAN node `node`; node_count() when it has none.
std::size_t node_index(const CanioBus& bus, uint8_t node) {
  for (std::size_t k = 0; k < bus.node_count(); ++k)
    if (bus.node_counters(k).node == node) return k;
  return bus.node_count();
}

}  // namespace

void CanioService::watch(std::vector<BusEvent>& events, bool first,
                         std::chrono::steady_clock::time_point now) {
  const canio::CanState s = bus_->can_state();
  if (!first && s != can_state_)
    events.push_back(
        {!canio::can_transmit(s),
         fmt::format("canio {}: controller {} -> {}{}", bus_->port_name(),
                     canio::to_string(can_state_), canio::to_string(s),
                     s == canio::CanState::BusOff
                         ? " (no frames until the controller restarts: restart-ms)"
                         : ""),
         s == canio::CanState::BusOff ? control::LogEvent::BusOff : control::LogEvent::BusState});
  can_state_ = s;
  if (first && !vbus_) {
    // Stale replay: without one-shot a controller retransmits a frame nobody acknowledges (all
    // nodes gone) until the bus returns, and the kernel's queue fills behind it: up to
    // txqueuelen old SYNCs and output objects go out when a node is back.
    const auto info = bus_->interface_info();
    const uint32_t per_cycle = bus_->tx_frames_per_cycle();
    if (!info.one_shot && info.txqueuelen > 2 * per_cycle)
      events.push_back(
          {true,
           fmt::format("canio {}: one-shot off and txqueuelen {}: after a silence up to {} "
                       "cycles of old SYNCs and output objects go out when a node is back; "
                       "ip link set {} down && ip link set {} type can one-shot on && ip link "
                       "set {} up (or txqueuelen {})",
                       bus_->port_name(), info.txqueuelen,
                       (info.txqueuelen + per_cycle - 1) / per_cycle, bus_->port_name(),
                       bus_->port_name(), bus_->port_name(), 2 * per_cycle),
           control::LogEvent::BusState, -1, -1, "stale-tx-replay"});
  }
  const auto& c = bus_->counters();
  uint64_t more = 0;
  const uint64_t full = c.tx_queue_full.load();
  if (first)
    tx_full_.said = full;
  else if (tx_full_.due(full, now, more))
    events.push_back({true, fmt::format("canio {}: TX queue full (ENOBUFS) {} time(s), frames "
                                        "dropped ({} in total; raise txqueuelen)",
                                        bus_->port_name(), more, full)});
  if (silent_.size() < bus_->options().axes.size()) {
    silent_.resize(bus_->options().axes.size());
    answered_.resize(bus_->options().axes.size());
  }
  for (std::size_t i = 0; i < bus_->options().axes.size(); ++i) {
    const auto& a = bus_->options().axes[i];
    const auto& ac = bus_->axis_counters(i);
    const bool silent = ac.silent.load() && bus_->state() != BusState::Down;
    if (!first && silent != silent_[i])
      events.push_back(
          {silent,
           silent ? fmt::format("canio node {}: silent (no complete sample of axis "
                                "'{}' for {} ms)",
                                a.node, a.name, bus_->options().bus.input_timeout_ms)
           : answered_[i]
               ? fmt::format("canio node {}: axis '{}' answering again", a.node, a.name)
               : fmt::format("canio node {}: axis '{}' answering (first samples)", a.node, a.name),
           silent ? control::LogEvent::NodeSilent : control::LogEvent::NodeOperational,
           static_cast<int>(a.node), static_cast<int>(i)});
    silent_[i] = silent;
    if (!silent) {
      answered_[i] = true;
      note_heard(a.node);
    }
  }
  canio::CanioNodeEvent e;
  while (bus_->poll_event(e)) on_node_event(e, events);
}

// The one place the daemon hears of a CAN node's lifecycle events (boot-up, missed heartbeat,
// EMCY, Start repeated, bus-off and restart): each is counted by the driver (status, metrics)
// and logged here with the node's journal fields. The daemon turns the boot-up and the missed
// heartbeat into flight-recorder incidents by their reason (incident_of() in daemon.cpp); the
// driver raises the bus-off itself on its cycle.
bool CanioService::note_heard(uint8_t node) {
  if (std::find(heard_.begin(), heard_.end(), node) != heard_.end()) return false;
  heard_.push_back(node);
  return true;
}

void CanioService::on_node_event(const canio::CanioNodeEvent& e, std::vector<BusEvent>& events) {
  using K = canio::CanioNodeEventKind;
  const std::string why(canio::to_string(e.kind));
  const bool first_contact = note_heard(e.node);
  switch (e.kind) {
    case K::BootUp:
      // A node's boot-up before anything else of it was heard is how a node powered with (or
      // after) the daemon says hello: nothing was lost, it is no incident.
      if (first_contact) {
        events.push_back({false,
                          fmt::format("canio node {}: boot-up (first contact): its axes are "
                                      "configured",
                                      e.node),
                          control::LogEvent::None, e.node, -1, "first-contact"});
        return;
      }
      events.push_back({true,
                        fmt::format("canio node {}: boot-up (the node reset and lost its "
                                    "configuration): its axes are down and configured again",
                                    e.node),
                        control::LogEvent::NodeReset, e.node, -1, why});
      return;
    case K::HeartbeatMissed:
      events.push_back({true,
                        fmt::format("canio node {}: heartbeat missed (none within {} ms): its "
                                    "axes are down until the configuration is checked again",
                                    e.node, e.detail),
                        control::LogEvent::NodeSilent, e.node, -1, why});
      return;
    case K::Emcy:
      events.push_back(
          {true,
           fmt::format("canio node {}: EMCY error code 0x{:04X}, error register 0x{:02X}, "
                       "vendor {:02X} {:02X} {:02X} {:02X} {:02X}",
                       e.node, e.emcy.error_code, e.emcy.error_register, e.emcy.vendor[0],
                       e.emcy.vendor[1], e.emcy.vendor[2], e.emcy.vendor[3], e.emcy.vendor[4]),
           control::LogEvent::None, e.node, -1, why});
      return;
    case K::StartRetry:
      events.push_back({true,
                        fmt::format("canio node {}: configured but no process data after NMT "
                                    "Start: Start sent again (next in {} ms)",
                                    e.node, e.detail),
                        control::LogEvent::NodeSilent, e.node, -1, why});
      return;
    case K::IdentityMismatch: {
      // The node's reason in the journal (DS1928_REASON): what differs.
      const std::size_t k = node_index(*bus_, e.node);
      const std::string what =
          k < bus_->node_count() ? canio::describe_identity(bus_->node_identity(k)) : why;
      events.push_back(
          {true,
           fmt::format("canio node {}: {}; {}", e.node, what,
                       bus_->options().identity_refuse
                           ? "the node is not started, its axes stay down (topology."
                             "on_mismatch: refuse); checked again with back-off"
                           : "configured and started anyway (topology.on_mismatch: warn)"),
           control::LogEvent::IdentificationFailed, e.node, -1, what});
      return;
    }
    case K::IdentityConfirmed:
      events.push_back({false,
                        fmt::format("canio node {}: identity as expected (canio.nodes[]): its "
                                    "modules are configured",
                                    e.node),
                        control::LogEvent::NodeOperational, e.node, -1, why});
      return;
    case K::BusOff:
      return;  // the controller's state change is logged above (watch())
    case K::BusRestarted:
      events.push_back({false,
                        "canio " + std::string(bus_->port_name()) +
                            ": controller back after bus-off: every node is checked (boot-up, "
                            "heartbeat or read-back) before its axes are trusted",
                        control::LogEvent::BusState, -1, -1, why});
      return;
  }
}

NodePhase CanioService::node_phase(std::size_t axis) const {
  if (axis >= bus_->options().axes.size()) return NodePhase::Unknown;
  const uint8_t node = bus_->options().axes[axis].node;
  const bool silent = bus_->axis_counters(axis).state.load() == canio::CanioAxisState::Silent;
  for (std::size_t k = 0; k < bus_->node_count(); ++k) {
    const canio::CanioNodeCounters& nc = bus_->node_counters(k);
    if (nc.node == node)
      return canio::node_phase(nc.nmt_state.load(std::memory_order_relaxed), silent,
                               nc.heartbeat_watched.load(std::memory_order_relaxed));
  }
  return NodePhase::Unknown;
}

std::string CanioService::axis_cause(std::size_t axis) const {
  if (axis >= bus_->options().axes.size()) return {};
  const canio::CanioAxisState s = bus_->axis_counters(axis).state.load();
  if (s == canio::CanioAxisState::Operational) return {};
  std::string why = bus_->axis_last_error(axis);
  if (why.empty()) why = bus_->axis_reason(axis);
  return fmt::format("canio node {}: {}", bus_->options().axes[axis].node, why);
}

BusService::Reported CanioService::reported_state() const {
  const BusState s = bus_->state();
  if (s != BusState::Operational) {
    Reported r = BusService::reported_state();
    if (s == BusState::Error)
      r.cause = fmt::format("canio {}: controller {}", bus_->port_name(),
                            canio::to_string(bus_->can_state()));
    return r;
  }
  // Per node: it answers when one of its axes is configured (its SDO server answered); it fails
  // when none is and one has an error or a state that says why; otherwise it is still being
  // configured for the first time.
  const auto& axes = bus_->options().axes;
  std::vector<uint8_t> nodes;
  for (const auto& a : axes)
    if (std::find(nodes.begin(), nodes.end(), a.node) == nodes.end()) nodes.push_back(a.node);
  std::size_t answering = 0;
  std::size_t failing = 0;
  std::string causes;
  for (const uint8_t node : nodes) {
    bool answers = false;
    std::string why;
    for (std::size_t i = 0; i < axes.size(); ++i) {
      if (axes[i].node != node) continue;
      const canio::CanioAxisState st = bus_->axis_counters(i).state.load();
      if (st == canio::CanioAxisState::Operational ||
          st == canio::CanioAxisState::AwaitingPosCycle) {
        answers = true;
        break;
      }
      if (!why.empty()) continue;
      why = bus_->axis_last_error(i);
      // Configuring, and Starting before the first repeated Start, are the normal way up.
      const std::size_t k = node_index(*bus_, node);
      const bool start_repeated =
          k < bus_->node_count() && bus_->node_counters(k).start_retries.load() > 0;
      if (why.empty() && st != canio::CanioAxisState::Configuring &&
          (st != canio::CanioAxisState::Starting || start_repeated))
        why = bus_->axis_reason(i);
    }
    if (answers) {
      ++answering;
    } else if (!why.empty()) {
      ++failing;
      causes += fmt::format("{}node {}: {}", causes.empty() ? "" : "; ", node, why);
    }
  }
  if (failing == 0 && answering == nodes.size()) return {"operational", {}};
  if (failing == 0) return {"booting", "the nodes are being configured over SDO"};
  if (answering == 0)
    return {"no_nodes", fmt::format("no node answers on {}: {}", bus_->port_name(), causes)};
  return {"degraded", fmt::format("{} of {} node(s) answer; {}", answering, nodes.size(), causes)};
}

void CanioService::status_extra(nlohmann::json& j) const {
  const auto info = bus_->interface_info();
  const auto pc = bus_->port_counters();
  const auto& c = bus_->counters();
  j["interface"] = std::string(bus_->port_name());
  j["transport"] = vbus_ ? "virtual" : "socketcan";
  j["can_state"] = std::string(canio::to_string(bus_->can_state()));
  j["bitrate"] = info.bitrate;
  j["restart_ms"] = info.restart_ms;
  j["one_shot"] = info.one_shot;
  j["txqueuelen"] = info.txqueuelen;
  j["response_window_us"] = bus_->options().response_window_us;
  j["last_window_us"] = static_cast<double>(c.last_window_ns.load()) / 1000.0;
  j["counters"] = {{"cycles", c.cycles.load()},
                   {"sync_sent", c.sync_sent.load()},
                   {"tx_queue_full", c.tx_queue_full.load()},
                   {"tx_failed", c.tx_failed.load()},
                   {"unexpected_ids", c.unexpected_ids.load()},
                   {"error_frames", c.error_frames.load()},
                   {"receive_errors", c.receive_errors.load()},
                   {"bus_off_cycles", c.bus_off_cycles.load()},
                   {"bus_off_events", pc.bus_off_events},
                   {"restarts", pc.restarts},
                   {"rx_frames", pc.rx_frames},
                   {"tx_frames", pc.tx_frames},
                   {"rx_kernel_drops", pc.rx_kernel_drops},
                   {"bus_errors_filtered", c.bus_errors_filtered.load()},
                   {"bus_restarts", c.bus_restarts.load()},
                   {"node_events_dropped", c.events_dropped.load()}};
  j["nmt"] = bus_->options().bus.nmt == CanNmt::Start ? "start" : "none";
  nlohmann::json canopen = nlohmann::json::array();
  for (std::size_t k = 0; k < bus_->node_count(); ++k) {
    const auto& nc = bus_->node_counters(k);
    const uint8_t st = nc.nmt_state.load();
    const uint64_t emcy = nc.last_emcy.load();
    nlohmann::json n = {
        {"node", nc.node},
        {"nmt_state", st == 0xFF ? std::string("unknown")
                                 : std::string(canio::to_string(static_cast<canio::NmtState>(st)))},
        {"nmt_starts", nc.nmt_starts.load()},
        {"start_retries", nc.start_retries.load()},
        {"boot_ups", nc.boot_ups.load()},
        {"heartbeat_watched", nc.heartbeat_watched.load()},
        {"heartbeats", nc.heartbeats.load()},
        {"heartbeat_misses", nc.heartbeat_misses.load()},
        {"emcys", nc.emcys.load()},
        {"identity", identity_json(bus_->node_identity(k))}};
    if (nc.emcys.load() > 0)
      n["last_emcy"] = {{"error_code", emcy & 0xFFFF},
                        {"error_register", (emcy >> 16) & 0xFF},
                        {"vendor",
                         {(emcy >> 24) & 0xFF, (emcy >> 32) & 0xFF, (emcy >> 40) & 0xFF,
                          (emcy >> 48) & 0xFF, (emcy >> 56) & 0xFF}}};
    canopen.push_back(std::move(n));
  }
  j["canopen_nodes"] = std::move(canopen);
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t i = 0; i < bus_->options().axes.size(); ++i) {
    const auto& a = bus_->options().axes[i];
    const auto& ac = bus_->axis_counters(i);
    axes.push_back({{"axis", i},
                    {"node", a.node},
                    {"input_ids", {a.ids.input[0], a.ids.input[1]}},
                    {"output_id", a.ids.output},
                    {"configured", ac.configured.load()},
                    {"state", std::string(canio::to_string(ac.state.load()))},
                    {"reason", bus_->axis_reason(i)},
                    {"unconfigurable", ac.unconfigurable.load()},
                    {"write_aborts", ac.write_aborts.load()},
                    {"unpaired", ac.unpaired.load()},
                    {"gated", ac.gated.load()},
                    {"unverified_writes", ac.unverified.load()},
                    {"rescans", ac.rescans.load()},
                    {"silent", ac.silent.load()},
                    {"samples", ac.samples.load()},
                    {"half_samples", ac.half_samples.load()},
                    {"missing", ac.missing.load()},
                    {"duplicates", ac.duplicates.load()},
                    {"wrong_length", ac.wrong_length.load()},
                    {"late_frames", ac.late_frames.load()},
                    {"sdo_transfers", ac.sdo_transfers.load()},
                    {"sdo_errors", ac.sdo_errors.load()},
                    {"configurations", ac.configurations.load()},
                    {"last_error", bus_->axis_last_error(i)}});
  }
  j["nodes"] = std::move(axes);
}

std::unique_ptr<BusService> make_canio_service(const DaemonConfig& config, std::string& why_not) {
  canio::CanioBusOptions options =
      canio::make_canio_options(config.canio, config.axes, config.cycle.period_us);
  options.identity_refuse = config.topology.refuse;
  std::unique_ptr<canio::CanPort> cycle_port;
  std::unique_ptr<canio::CanPort> sdo_port;
  std::shared_ptr<canio::VirtualCanBus> vbus;
  if (!config.canio.virtual_bus.empty()) {
    auto bus = canio::VirtualCanBus::open_shared(config.canio.virtual_bus,
                                                 canio::virtual_bus_options(config.canio.bitrate));
    if (!bus) {
      why_not =
          fmt::format("canio: virtual bus '{}': {}", config.canio.virtual_bus,
                      canio::VirtualCanBus::open_error_text(config.canio.virtual_bus, bus.error()));
      return nullptr;
    }
    vbus = bus.value();
    for (auto* port : {&cycle_port, &sdo_port}) {
      canio::VirtualPortOptions po;
      po.name = config.canio.virtual_bus;
      po.bitrate = config.canio.bitrate;
      auto p = vbus->open_port(po);
      if (!p) {
        why_not = fmt::format("canio: virtual bus '{}': {}", config.canio.virtual_bus,
                              p.error().message());
        return nullptr;
      }
      *port = std::move(p.value());
    }
  } else {
    for (auto* port : {&cycle_port, &sdo_port}) {
      canio::SocketCanOptions so;
      so.interface = config.canio.interface;
      so.expected_bitrate = config.canio.bitrate;
      canio::SocketCanOpen opened = canio::SocketCanPort::open(so);
      if (!opened.port) {
        why_not = opened.message.empty()
                      ? fmt::format("canio: {}: {}", config.canio.interface, opened.error.message())
                      : "canio: " + opened.message;
        return nullptr;
      }
      *port = std::move(opened.port);
    }
  }
  // State and bit rate as the interface reports them (SocketCanPort::open checked them already;
  // this words the same error for every port kind).
  if (std::string problem = canio::check_interface(*cycle_port, config.canio.bitrate);
      !problem.empty()) {
    why_not = "canio: " + problem;
    return nullptr;
  }
  try {
    // Both ports pass a capture point (ds1928ctl capture); it only copies while a capture runs.
    const std::string name(cycle_port->name());
    auto cycle = std::make_unique<capture::CapturingCanPort>(std::move(cycle_port), name,
                                                             config.capture.ring_frames);
    auto sdo = std::make_unique<capture::CapturingCanPort>(std::move(sdo_port), name,
                                                           config.capture.ring_frames);
    cycle->tap().set_description("CAN-I/O cycle port (SYNC, objects, error frames)");
    sdo->tap().set_description("CAN-I/O SDO port");
    capture::Tap& cycle_tap = cycle->tap();
    capture::Tap& sdo_tap = sdo->tap();
    auto bus = std::make_unique<CanioBus>(options, std::move(cycle), std::move(sdo));
    auto service = std::make_unique<CanioService>(std::move(bus), std::move(vbus));
    service->add_capture_tap(cycle_tap);
    service->add_capture_tap(sdo_tap);
    return service;
  } catch (const std::exception& e) {
    why_not = fmt::format("canio: {}", e.what());
    return nullptr;
  }
}

}  // namespace ds1928
