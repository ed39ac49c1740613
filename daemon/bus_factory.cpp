// The bus kinds the daemon knows, how each is created, and the parts of BusService every kind
// shares. Adding a bus kind = one driver (a BusDriver that serves register requests as a
// RegisterTarget of its RegisterPath, core/register_path.hpp), one service in the shape of the
// others (<kind>_service.hpp/.cpp with its factory, <kind>_metrics.cpp for its metric families)
// and one row in kKinds.
#include <fmt/format.h>

#include <array>

#include "bus_service.hpp"
#include "daemon.hpp"

namespace ds1928 {
namespace {

using Factory = std::unique_ptr<BusService> (*)(const DaemonConfig&, std::string&);

constexpr std::array<std::string_view, 2> kPowerlinkCommands{"pl-pres", "pl-preq-set"};

struct Kind {
  BusKind kind;
  Factory make;
};
constexpr std::array<Kind, 3> kKinds{{{BusKind::Simulated, &make_simulated_service},
                                      {BusKind::Powerlink, &make_powerlink_service},
                                      {BusKind::Canio, &make_canio_service}}};

constexpr std::array<BusCommandSet, 1> kCommandSets{
    {{BusKind::Powerlink, "powerlink", kPowerlinkCommands}}};

}  // namespace

bool SaidCounter::due(uint64_t value, std::chrono::steady_clock::time_point now, uint64_t& more) {
  if (value <= said || now - at < kRepeat) return false;
  more = value - said;
  said = value;
  at = now;
  return true;
}

BusService::Reported BusService::reported_state() const {
  const BusState s = driver().state();
  Reported r{std::string(to_string(s)), {}};
  switch (s) {
    case BusState::Operational:
      break;
    case BusState::Booting:
      r.cause = "the nodes are being started and configured";
      break;
    case BusState::Down:
      r.cause = "the bus is stopped";
      break;
    case BusState::Error:
      r.cause = "the bus driver reports an error";
      break;
  }
  return r;
}

std::string BusService::axis_cause(std::size_t) const {
  return {};
}

NodePhase BusService::node_phase(std::size_t) const {
  switch (driver().state()) {
    case BusState::Operational:
      return NodePhase::Operational;
    case BusState::Booting:
      return NodePhase::Boot;
    case BusState::Down:
    case BusState::Error:
      break;
  }
  return NodePhase::Unknown;
}

nlohmann::json BusService::status_json() const {
  Reported r = reported_state();
  nlohmann::json j{{"kind", std::string(driver().name())}, {"state", r.state}};
  if (r.state != "operational") j["cause"] = std::move(r.cause);
  status_extra(j);
  return j;
}

void BusService::status_extra(nlohmann::json&) const {}

void BusService::register_commands(control::Server&, const SocketConfig&) {}

void BusService::watch(std::vector<BusEvent>&, bool, std::chrono::steady_clock::time_point) {}

void BusService::append_metrics(metrics::Exposition&) const {}

void log_bus_event(const BusEvent& e, std::string_view bus) {
  control::log_event(e.warning ? spdlog::level::warn : spdlog::level::info,
                     {e.event, bus, e.node, e.axis, e.reason}, e.text);
}

std::span<const BusCommandSet> bus_commands() noexcept {
  return kCommandSets;
}

std::unique_ptr<BusService> make_bus_service(const DaemonConfig& config, std::string& why_not) {
  for (const Kind& k : kKinds)
    if (k.kind == config.bus) return k.make(config, why_not);
  why_not = fmt::format("bus '{}' has no driver in this build", to_string(config.bus));
  return nullptr;
}

void register_bus_commands(control::Server& server, BusService& bus, const DaemonConfig& config) {
  bus.register_commands(server, config.socket);
  // Another kind's commands answer "not_<kind>" here, so a client learns why, not "unknown".
  for (const BusCommandSet& set : bus_commands()) {
    if (set.kind == config.bus) continue;
    for (std::string_view command : set.commands) {
      server.add_command(
          std::string(command),
          [kind = std::string(set.kind_name), have = std::string(bus.driver().name())](
              const control::Request& req, control::Reply reply) {
            reply.error("not_" + kind, "'" + req.command() + "' needs the " + kind +
                                           " bus; this one is '" + have + "'");
          });
    }
  }
}

std::vector<BusEvent> BusWatch::poll(BusService& bus, std::chrono::steady_clock::time_point now) {
  std::vector<BusEvent> events;
  BusService::Reported now_state = bus.reported_state();
  if (!seen_ || now_state.state != state_) {
    // The first look reports nothing: the start is logged on its own.
    if (seen_)
      events.push_back(
          {now_state.state != "operational",
           fmt::format("bus {}: {} -> {}{}", bus.driver().name(), state_, now_state.state,
                       now_state.cause.empty() ? std::string() : ": " + now_state.cause),
           control::LogEvent::BusState, -1, -1, now_state.cause});
    state_ = std::move(now_state.state);
  }
  bus.watch(events, !seen_, now);
  seen_ = true;
  return events;
}

}  // namespace ds1928
