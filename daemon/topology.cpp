#include "topology.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "endat_service.hpp"
#include "service/journal.hpp"

namespace ds1928 {

using json = nlohmann::json;

namespace {

std::string join(const std::vector<std::string>& parts) {
  std::string out;
  for (const auto& p : parts) out += (out.empty() ? "" : "; ") + p;
  return out;
}

json hex_or_null(const std::optional<uint32_t>& v) {
  if (!v) return nullptr;
  return fmt::format("0x{:08X}", *v);
}

}  // namespace

std::vector<std::string> encoder_differences(const ExpectedEncoder& e,
                                             const endat::Identification& f) {
  std::vector<std::string> d;
  const std::string id = f.id.to_string();
  const std::string serial = f.serial.to_string();
  if (!e.id_number.empty() && e.id_number != id)
    d.push_back(fmt::format("id_number: expected '{}', found '{}'", e.id_number, id));
  if (!e.serial_number.empty() && e.serial_number != serial)
    d.push_back(fmt::format("serial_number: expected '{}', found '{}'", e.serial_number, serial));
  if (e.position_bits != 0 && e.position_bits != f.position_bits)
    d.push_back(
        fmt::format("position_bits: expected {}, found {}", e.position_bits, f.position_bits));
  return d;
}

std::string_view to_string(IdentityState s) noexcept {
  switch (s) {
    case IdentityState::Unchecked:
      return "unchecked";
    case IdentityState::Pending:
      return "pending";
    case IdentityState::Confirmed:
      return "confirmed";
    case IdentityState::Mismatch:
      return "mismatch";
    case IdentityState::Unreadable:
      return "unreadable";
  }
  return "?";
}

Topology::Topology(const DaemonConfig& config, CycleWork& work)
    : config_(config), work_(work), differences_(config.axes.size()) {}

void Topology::on_identified(std::size_t axis, std::error_code error,
                             const endat::Identification* found) {
  if (axis >= config_.axes.size()) return;
  const AxisConfig& a = config_.axes[axis];
  if (!a.expected_encoder.any()) return;
  auto& state = work_.counters(axis).identity;
  const char* consequence = config_.topology.refuse
                                ? "the axis stays bus_down (topology.on_mismatch: refuse)"
                                : "positions are published anyway (topology.on_mismatch: warn)";
  if (error || found == nullptr) {
    differences_[axis] = "identification failed: " + (error ? error.message() : std::string("?"));
    state.store(static_cast<uint8_t>(IdentityState::Unreadable), std::memory_order_relaxed);
    control::log_event(
        spdlog::level::warn,
        {control::LogEvent::IdentificationFailed,
         {},
         a.node,
         static_cast<int>(axis),
         differences_[axis]},
        fmt::format("axis {} ({}): the expected encoder cannot be confirmed ({}); {}", axis, a.name,
                    differences_[axis], consequence));
    return;
  }
  const auto d = encoder_differences(a.expected_encoder, *found);
  if (d.empty()) {
    differences_[axis].clear();
    state.store(static_cast<uint8_t>(IdentityState::Confirmed), std::memory_order_relaxed);
    spdlog::info("axis {} ({}): encoder as expected (ID {}, serial {})", axis, a.name,
                 found->id.to_string(), found->serial.to_string());
    return;
  }
  // The reason is the difference alone: status shows it beside the state ("mismatch").
  differences_[axis] = join(d);
  state.store(static_cast<uint8_t>(IdentityState::Mismatch), std::memory_order_relaxed);
  control::log_event(spdlog::level::err,
                     {control::LogEvent::IdentificationFailed,
                      {},
                      a.node,
                      static_cast<int>(axis),
                      differences_[axis]},
                     fmt::format("axis {} ({}): encoder mismatch: {}; {}", axis, a.name,
                                 differences_[axis], consequence));
}

std::string Topology::reason(std::size_t axis) const {
  if (axis >= differences_.size()) return {};
  const auto s = static_cast<IdentityState>(work_.counters(axis).identity.load());
  if (s == IdentityState::Pending && config_.topology.refuse)
    return "waiting for the encoder identification (axes[].expected_encoder)";
  return differences_[axis];
}

json Topology::topology_json(const EnDatService* endat, const json& bus_status) const {
  json axes = json::array();
  for (std::size_t i = 0; i < config_.axes.size(); ++i) {
    const AxisConfig& a = config_.axes[i];
    const auto state = static_cast<IdentityState>(work_.counters(i).identity.load());
    json expected = nullptr;
    if (a.expected_encoder.any()) {
      expected = json::object();
      if (!a.expected_encoder.id_number.empty())
        expected["id_number"] = a.expected_encoder.id_number;
      if (!a.expected_encoder.serial_number.empty())
        expected["serial_number"] = a.expected_encoder.serial_number;
      if (a.expected_encoder.position_bits != 0)
        expected["position_bits"] = a.expected_encoder.position_bits;
    }
    json found = nullptr;
    if (endat != nullptr) {
      if (const auto& id = endat->identification(i)) {
        found = {{"id_number", id->id.to_string()},
                 {"serial_number", id->serial.to_string()},
                 {"position_bits", id->position_bits},
                 {"endat", id->command_set == endat::CommandSet::EnDat22 ? "2.2" : "2.1"},
                 {"type", id->type == endat::EncoderType::Rotary ? "rotary" : "linear"}};
      }
    }
    axes.push_back({{"axis", i},
                    {"name", a.name},
                    {"node", a.node},
                    {"slot", a.slot},
                    {"expected", std::move(expected)},
                    {"found", std::move(found)},
                    {"state", std::string(to_string(state))},
                    {"difference", differences_[i].empty() ? json(nullptr) : json(differences_[i])},
                    {"held_down", config_.topology.refuse && state != IdentityState::Unchecked &&
                                      state != IdentityState::Confirmed}});
  }
  json nodes = json::array();
  if (config_.bus == BusKind::Powerlink) {
    for (const auto& n : config_.powerlink.nodes) {
      json found = nullptr;
      json difference = nullptr;
      std::string boot;
      if (bus_status.contains("nodes")) {
        for (const auto& s : bus_status["nodes"]) {
          if (s.value("node", -1) != n.node_id) continue;
          found = {{"vendor_id", fmt::format("0x{:08X}", s.value("vendor_id", 0u))},
                   {"product_code", fmt::format("0x{:08X}", s.value("product_code", 0u))}};
          boot = s.value("boot", std::string());
          if (s.contains("configuration") && !s["configuration"]["identity_mismatch"].is_null())
            difference = s["configuration"]["identity_mismatch"];
          // Refused at the IdentResponse: the MN's reason stays the node's last error.
          const std::string last = s.value("last_error", std::string());
          if (difference.is_null() && last.find("identity") != std::string::npos) difference = last;
        }
      }
      nodes.push_back({{"node", n.node_id},
                       {"expected",
                        {{"vendor_id", hex_or_null(n.vendor_id)},
                         {"product_code", hex_or_null(n.product_code)},
                         {"revision_no", hex_or_null(n.revision_no)},
                         {"serial_no", hex_or_null(n.serial_no)}}},
                       {"found", std::move(found)},
                       {"boot", boot},
                       {"difference", std::move(difference)}});
    }
  }
  if (config_.bus == BusKind::Canio && bus_status.contains("canopen_nodes")) {
    // CAN-I/O: the driver read each node's identity objects (canio.nodes[]) before configuring
    // it; status carries expected and found (CanioService).
    for (const auto& s : bus_status["canopen_nodes"]) {
      const json id = s.value("identity", json::object());
      const std::string state = id.value("state", std::string("unchecked"));
      nodes.push_back({{"node", s.value("node", 0)},
                       {"expected", id.value("expected", json())},
                       {"found", id.value("found", json())},
                       {"boot", s.value("nmt_state", std::string()) == "unknown"
                                    ? std::string()
                                    : s.value("nmt_state", std::string())},
                       {"state", state},
                       {"difference", id.value("difference", json())},
                       {"held_down", config_.topology.refuse &&
                                         (state == "mismatch" || state == "unreadable")}});
    }
  }
  return {{"on_mismatch", config_.topology.refuse ? "refuse" : "warn"},
          {"bus", std::string(to_string(config_.bus))},
          {"axes", std::move(axes)},
          {"nodes", std::move(nodes)}};
}

void Topology::append_metrics(metrics::Exposition& out) const {
  out.family("ds1928_axis_identity_mismatch", metrics::Type::Gauge,
             "1 while the encoder of an axis is not the expected one (or cannot be identified).");
  for (std::size_t i = 0; i < config_.axes.size(); ++i) {
    const auto s = static_cast<IdentityState>(work_.counters(i).identity.load());
    out.sample({{"axis", std::to_string(i)}, {"name", config_.axes[i].name}},
               uint64_t{s == IdentityState::Mismatch || s == IdentityState::Unreadable ? 1u : 0u});
  }
}

}  // namespace ds1928
