// The `canio` section: interface and bit rate, SYNC, identifiers (CANopen predefined connection
// set or an explicit table), acyclic transport, timeouts; and the checks that need the axes and
// the cycle (node numbers 1..127, MTU 3..5, identifier collisions, the cycle's bits on the wire).
#include "config/config_canio.hpp"

#include <iomanip>
#include <set>

#include "canio/bit_budget.hpp"
#include "core/register_catalogue.hpp"

namespace ds1928 {

CanioAxisIds canio_axis_ids(const CanioBusConfig& canio, const AxisConfig& axis,
                            std::size_t index) {
  CanioAxisConfig a;
  if (index < canio.axes.size()) a = canio.axes[index];
  CanioAxisIds ids;
  if (canio.identifiers == CanIdScheme::Explicit) {
    ids.input[0] = a.input_ids[0].value_or(0);
    ids.input[1] = a.input_ids[1].value_or(0);
    ids.output = a.output_id.value_or(0);
    return ids;
  }
  // CiA 301 predefined set: TPDO k → 0x180 + 0x100·(k−1) + node, RPDO k → 0x200 + 0x100·(k−1) +
  // node. CiA 401 puts digital I/O in PDO1 and analog channels from PDO2 on: analog logical slot
  // s (8 bytes, one CAN object) → PDO s + 1. The module's input objects are its two slots; its
  // one output object is its first slot's RPDO.
  const uint32_t s = a.first_analog_slot;
  ids.input[0] = 0x180 + 0x100 * s + axis.node;
  ids.input[1] = 0x180 + 0x100 * (s + 1) + axis.node;
  ids.output = 0x200 + 0x100 * s + axis.node;
  return ids;
}

namespace config_detail {
namespace {

constexpr uint32_t kMaxStandardId = 0x7FF;
constexpr uint32_t kMaxPredefinedPdo = 4;  // TPDO1..4 / RPDO1..4 in the predefined set

std::string hex_id(uint32_t id) {
  std::ostringstream o;
  o << "0x" << std::hex << std::uppercase << std::setw(3) << std::setfill('0') << id;
  return o.str();
}

void parse_canio_axis(Section s, CanioAxisConfig& a) {
  s.integer("first_analog_slot", a.first_analog_slot, 1, 64,
            "(the module's first of its 2 analog logical slots behind the bus controller)");
  if (const YAML::Node* v = s.find("input_ids"); v && !v->IsNull()) {
    if (!v->IsSequence() || v->size() != 2) {
      s.error(
          "input_ids",
          "expected a list of 2 identifiers [object 1 (position), object 2], got " + describe(*v));
    } else {
      for (std::size_t k = 0; k < 2; ++k) {
        const YAML::Node n = (*v)[k];
        const IntParse p = is_plain(n) ? parse_integer(n.Scalar()) : IntParse{};
        if (!is_plain(n) || p.status != IntParse::Status::Ok || p.value < 0 ||
            p.value > kMaxStandardId) {
          s.diag().error(loc_of(n.Mark()), s.child("input_ids") + "[" + std::to_string(k) + "]",
                         "expected an 11-bit CAN identifier 0..0x7FF, got " + describe(n));
          continue;
        }
        a.input_ids[k] = static_cast<uint32_t>(p.value);
      }
    }
  }
  s.optional_integer("output_id", a.output_id, 0, kMaxStandardId);
  s.finish();
}

}  // namespace

void parse_canio(Section s, CanioBusConfig& c) {
  if (s.text("interface", c.interface, 15) && !valid_interface_name(c.interface)) {
    s.error("interface", "'" + c.interface + "' is not a network interface name");
  }
  if (s.integer("bitrate", c.bitrate, 0, kU32, "bit/s")) {
    constexpr std::array<uint32_t, 9> kRates{10000,  20000,  50000,  100000, 125000,
                                             250000, 500000, 800000, 1000000};
    if (std::find(kRates.begin(), kRates.end(), c.bitrate) == kRates.end()) {
      s.error("bitrate", std::to_string(c.bitrate) +
                             " is not a CAN bit rate; expected one of 10000, 20000, 50000, 100000, "
                             "125000, 250000, 500000, 800000, 1000000");
    }
  }
  s.integer("response_timeout_us", c.response_timeout_us, 1, 100000, "µs");
  s.integer("input_timeout_ms", c.input_timeout_ms, 1, 60000, "ms");
  s.choice("byte_order", c.little_endian, {{"little", true}, {"big", false}});
  {
    Section sync = s.section("sync");
    sync.boolean("enabled", c.sync_enabled);
    sync.integer("id", c.sync_id, 0, kMaxStandardId, "(11-bit CAN identifier)");
    sync.finish();
  }
  s.choice("identifiers", c.identifiers,
           {{"canopen_predefined", CanIdScheme::CanopenPredefined},
            {"explicit", CanIdScheme::Explicit}});
  for (auto& item : s.list("axes")) {
    CanioAxisConfig a;
    parse_canio_axis(Section(s.diag(), item.node, item.path, item.at), a);
    c.axes.push_back(a);
  }
  {
    Section acyclic = s.section("acyclic");
    acyclic.choice(
        "transport", c.acyclic,
        {{"canopen_sdo", CanAcyclicTransport::CanopenSdo}, {"none", CanAcyclicTransport::None}});
    acyclic.integer("sdo_timeout_ms", c.sdo_timeout_ms, 1, 10000, "ms");
    std::map<uint16_t, Loc> seen;
    for (auto& item : acyclic.list("sdo_objects")) {
      Section o(s.diag(), item.node, item.path, item.at);
      uint16_t reg = 0;
      uint16_t index = 0;
      uint8_t subindex = 0;
      const bool ok = o.integer("register", reg, 1, kU16) & o.integer("index", index, 1, kU16) &
                      o.integer("subindex", subindex, 0, kU8);
      if (ok && !register_size(reg)) {
        o.error("register",
                std::to_string(reg) + " is not an X20DS1928 register (docs/registers.md)");
      } else if (ok) {
        if (const auto [it, fresh] = seen.emplace(reg, o.value_at("register")); !fresh) {
          o.error("register",
                  "register " + std::to_string(reg) + " is already mapped at " + where(it->second));
        } else {
          c.sdo_overrides[reg] = {index, subindex};
        }
      }
      o.finish();
    }
    acyclic.finish();
  }
  s.text("virtual_bus", c.virtual_bus, 200);
  s.finish();
}

void check_canio(Diagnostics& diag, const DaemonConfig& c, const YAML::Node& doc) {
  const CanioBusConfig& k = c.canio;
  const YAML::Node axes_node = doc.IsMap() ? doc["axes"] : YAML::Node();
  auto axis_doc = [&](std::size_t i) {
    return axes_node.IsSequence() && i < axes_node.size() ? axes_node[i] : YAML::Node();
  };
  auto axis_loc = [&](std::size_t i, std::initializer_list<std::string_view> keys) {
    const YAML::Node n = axis_doc(i);
    return n.IsDefined() && n.IsMap() ? locate(n, keys) : locate(doc, {"axes"});
  };
  const YAML::Node canio_axes =
      doc.IsMap() && doc["canio"].IsMap() ? doc["canio"]["axes"] : YAML::Node();
  auto canio_axis_loc = [&](std::size_t i, std::string_view key) {
    if (canio_axes.IsSequence() && i < canio_axes.size() && canio_axes[i].IsMap())
      return locate(canio_axes[i], {key});
    return locate(doc, {"canio", "identifiers"});
  };

  if (k.axes.size() > c.axes.size()) {
    diag.error(locate(doc, {"canio", "axes"}), "canio.axes",
               std::to_string(k.axes.size()) + " entries but only " +
                   std::to_string(c.axes.size()) +
                   " axes are configured (canio.axes[i] describes axes[i])");
  }
  if (k.response_timeout_us >= c.cycle.period_us) {
    diag.error(locate(doc, {"canio", "response_timeout_us"}), "canio.response_timeout_us",
               "response_timeout_us (" + std::to_string(k.response_timeout_us) +
                   ") must be less than cycle.period_us (" + std::to_string(c.cycle.period_us) +
                   ")");
  }

  // Every identifier on the bus, with who uses it, to name both ends of a collision.
  std::map<uint32_t, std::string> used;
  auto claim = [&](uint32_t id, const std::string& who, Loc at, const std::string& key) {
    if (const auto [it, fresh] = used.emplace(id, who); !fresh) {
      diag.error(
          at, key,
          "CAN identifier " + hex_id(id) + " of " + who + " is already used by " + it->second);
    }
  };
  if (k.sync_enabled)
    claim(k.sync_id, "the SYNC frame", locate(doc, {"canio", "sync", "id"}), "canio.sync.id");

  std::set<uint8_t> sdo_nodes;
  for (std::size_t i = 0; i < c.axes.size(); ++i) {
    const AxisConfig& a = c.axes[i];
    const std::string path = "axes[" + std::to_string(i) + "]";
    if (a.node < 1 || a.node > 127) {
      diag.error(axis_loc(i, {"node"}), path + ".node",
                 std::to_string(a.node) +
                     " is out of range 1..127 (CAN-I/O / CANopen node number of the bus "
                     "controller)");
      continue;
    }
    for (auto [key, mtu] : {std::pair{"input_mtu", a.module.input_mtu},
                            std::pair{"output_mtu", a.module.output_mtu}}) {
      if (mtu < 3) {
        diag.error(axis_loc(i, {"module", key}), path + ".module." + key,
                   std::to_string(mtu) +
                       " is below 3: the module's Flatstream MTU is 3..27 bytes (datasheet "
                       "§11.9.4.1), and function model 254 carries at most 5");
      }
    }
    const std::string who = path + " (" + a.name + ")";
    if (k.identifiers == CanIdScheme::Explicit) {
      const CanioAxisConfig ca = i < k.axes.size() ? k.axes[i] : CanioAxisConfig{};
      if (!ca.input_ids[0] || !ca.input_ids[1] || !ca.output_id) {
        diag.error(
            i < k.axes.size() ? canio_axis_loc(i, "input_ids")
                              : locate(doc, {"canio", "identifiers"}),
            "canio.axes[" + std::to_string(i) + "]",
            "identifiers: explicit needs input_ids [object 1, object 2] and output_id for " + who);
        continue;
      }
    } else {
      const uint8_t s = i < k.axes.size() ? k.axes[i].first_analog_slot : uint8_t{1};
      if (s + 2u > kMaxPredefinedPdo) {
        diag.error(canio_axis_loc(i, "first_analog_slot"),
                   "canio.axes[" + std::to_string(i) + "].first_analog_slot",
                   "analog slots " + std::to_string(s) + " and " + std::to_string(s + 1) +
                       " need TPDO" + std::to_string(s + 1) + " and TPDO" + std::to_string(s + 2) +
                       "; the CANopen predefined connection set has TPDO1..4 only: use "
                       "identifiers: explicit");
        continue;
      }
    }
    const CanioAxisIds ids = canio_axis_ids(k, a, i);
    const Loc ids_at = k.identifiers == CanIdScheme::Explicit ? canio_axis_loc(i, "input_ids")
                                                              : axis_loc(i, {"node"});
    const std::string ids_key = k.identifiers == CanIdScheme::Explicit
                                    ? "canio.axes[" + std::to_string(i) + "]"
                                    : path + ".node";
    claim(ids.input[0], who + " input object 1", ids_at, ids_key);
    claim(ids.input[1], who + " input object 2", ids_at, ids_key);
    claim(ids.output, who + " output object", ids_at, ids_key);
    if (k.acyclic == CanAcyclicTransport::CanopenSdo && sdo_nodes.insert(a.node).second) {
      claim(0x580 + a.node, "the SDO response of node " + std::to_string(a.node), ids_at, ids_key);
      claim(0x600 + a.node, "the SDO request of node " + std::to_string(a.node), ids_at, ids_key);
    }
  }

  // Bits on the wire per cycle (worst-case stuffing) against the period.
  canio::CycleLoad load;
  load.modules = static_cast<uint32_t>(c.axes.size());
  load.bitrate = k.bitrate;
  load.sync = k.sync_enabled;
  const canio::CycleFit fit =
      canio::check_cycle(load, static_cast<int64_t>(c.cycle.period_us) * 1000);
  if (!fit.fits && k.bitrate > 0) {
    const int64_t need_us = (fit.budget.time_worst_case_ns + 999) / 1000;
    diag.error(locate(doc, {"cycle", "period_us"}), "cycle.period_us",
               std::to_string(c.cycle.period_us) +
                   " µs is too short for the CAN-I/O bus: " + std::to_string(fit.budget.frames) +
                   " frames a cycle (" + std::to_string(c.axes.size()) + " module(s) × 3" +
                   (k.sync_enabled ? " + SYNC" : "") + ") are " +
                   std::to_string(fit.budget.bits_worst_case) +
                   " bits with worst-case stuffing = " + std::to_string(need_us) + " µs at " +
                   std::to_string(k.bitrate) + " bit/s, " + std::to_string(-fit.margin_ns / 1000) +
                   " µs more than the period; use period_us ≥ " + std::to_string(need_us) +
                   ", fewer modules or a higher bit rate");
  }
}

void dump_canio(std::ostream& o, const CanioBusConfig& c) {
  o << "canio:\n"
    << "  interface: \"" << c.interface << "\"\n"
    << "  bitrate: " << c.bitrate << "\n"
    << "  response_timeout_us: " << c.response_timeout_us << "\n"
    << "  input_timeout_ms: " << c.input_timeout_ms << "\n"
    << "  byte_order: " << (c.little_endian ? "little" : "big") << "\n"
    << "  sync:\n"
    << "    enabled: " << (c.sync_enabled ? "true" : "false") << "\n"
    << "    id: " << hex_id(c.sync_id) << "\n"
    << "  identifiers: "
    << (c.identifiers == CanIdScheme::Explicit ? "explicit" : "canopen_predefined") << "\n";
  if (!c.axes.empty()) {
    o << "  axes:\n";
    for (const CanioAxisConfig& a : c.axes) {
      o << "    - first_analog_slot: " << int(a.first_analog_slot) << "\n";
      if (a.input_ids[0] && a.input_ids[1])
        o << "      input_ids: [" << hex_id(*a.input_ids[0]) << ", " << hex_id(*a.input_ids[1])
          << "]\n";
      if (a.output_id) o << "      output_id: " << hex_id(*a.output_id) << "\n";
    }
  }
  o << "  acyclic:\n"
    << "    transport: " << (c.acyclic == CanAcyclicTransport::None ? "none" : "canopen_sdo")
    << "\n"
    << "    sdo_timeout_ms: " << c.sdo_timeout_ms << "\n";
  if (!c.sdo_overrides.empty()) {
    o << "    sdo_objects:\n";
    for (const auto& [reg, obj] : c.sdo_overrides)
      o << "      - {register: " << reg << ", index: 0x" << std::hex << std::uppercase << obj.first
        << ", subindex: 0x" << int(obj.second) << std::dec << "}\n";
  }
  if (!c.virtual_bus.empty()) o << "  virtual_bus: \"" << c.virtual_bus << "\"\n";
}

}  // namespace config_detail
}  // namespace ds1928
