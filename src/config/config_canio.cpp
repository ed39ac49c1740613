// The `canio` section: interface and bit rate, SYNC, identifiers (CANopen predefined connection
// set or an explicit table), acyclic transport, timeouts; and the checks that need the axes and
// the cycle (node numbers 1..127, identifier collisions, the response window against the wire time,
// the bus load against max_bus_load).
#include "config/config_canio.hpp"

#include <algorithm>
#include <iomanip>
#include <set>
#include <sstream>

#include "config/config_sdo_objects.hpp"

namespace ds1928::config_detail {
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
  s.integer("response_timeout_us", c.response_timeout_us, 0, 100000,
            "µs (0: derived from the bit budget)");
  s.integer("node_reaction_us", c.node_reaction_us, 0, 100000, "µs");
  s.real("max_bus_load", c.max_bus_load, 0.05, 1.0);
  s.choice("verify", c.verify, {{"readback", CanVerify::Readback}, {"none", CanVerify::None}});
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
    acyclic.integer("sdo_interval_us", c.sdo_interval_us, 0, 10'000'000, "µs");
    acyclic.integer("info_interval_ms", c.info_interval_ms, 10, 3'600'000, "ms");
    parse_sdo_objects(acyclic, "sdo_objects", c.sdo_overrides);
    acyclic.finish();
  }
  s.choice("nmt", c.nmt, {{"start", CanNmt::Start}, {"none", CanNmt::None}});
  for (auto& item : s.list("nodes")) {
    Section n(s.diag(), item.node, item.path, item.at);
    CanioNodeOptions o;
    n.integer("node", o.node, 1, 127, "(CANopen node id of the bus controller)");
    n.integer("heartbeat_ms", o.heartbeat_ms, 0, 65535,
              "ms (object 0x1017 is 16 bit; 0: no heartbeat watched)");
    n.integer("heartbeat_timeout_ms", o.heartbeat_timeout_ms, 0, 65535 * 2,
              "ms (0: 1.5 × heartbeat_ms)");
    // The identity to expect (CiA 301 0x1000, 0x1018/1..4), the keys of powerlink.nodes[].
    n.optional_integer("device_type", o.identity.device_type, 0, kU32);
    if (n.optional_integer("vendor_id", o.identity.vendor_id, 0, kU32) && o.identity.vendor_id &&
        *o.identity.vendor_id == 0)
      n.error("vendor_id", "0 is not a vendor-ID (CiA 301: 0x00000000 marks an invalid one)");
    n.optional_integer("product_code", o.identity.product_code, 0, kU32);
    n.optional_integer("revision_no", o.identity.revision_no, 0, kU32);
    n.optional_integer("serial_no", o.identity.serial_no, 0, kU32);
    n.finish();
    if (std::any_of(c.nodes.begin(), c.nodes.end(),
                    [&](const CanioNodeOptions& x) { return x.node == o.node; }))
      n.error("node", "node " + std::to_string(o.node) + " is listed twice in canio.nodes");
    else
      c.nodes.push_back(o);
  }
  s.integer("stall_limit", c.stall_limit, 0, 100000,
            "cycles (0: derived from the EnDat cycle and the period)");
  s.boolean("allow_manual_restart", c.allow_manual_restart);
  s.text("virtual_bus", c.virtual_bus, 200);
  s.finish();
}

void check_canio(const BusDocument& d) {
  Diagnostics& diag = d.diag;
  const DaemonConfig& c = d.config;
  const YAML::Node& doc = d.doc;
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
  const CanioTiming timing = canio_timing(k, c.axes.size(), c.cycle.period_us);
  if (k.bitrate > 0 && k.response_timeout_us != 0 && k.response_timeout_us < timing.min_window_us) {
    diag.error(locate(doc, {"canio", "response_timeout_us"}), "canio.response_timeout_us",
               std::to_string(k.response_timeout_us) +
                   " µs is shorter than the cycle's frames take " + "on the wire at " +
                   std::to_string(k.bitrate) + " bit/s (SYNC + " + std::to_string(c.axes.size()) +
                   " module(s) × 3 objects + one frame already on the wire, worst-case " +
                   "stuffing): the minimum is " + std::to_string(timing.min_window_us) +
                   " µs; leave it out (0) to use " + std::to_string(timing.derived_window_us) +
                   " µs (wire time + node_reaction_us " + std::to_string(k.node_reaction_us) + ")");
  } else if (k.bitrate > 0 && timing.window_us + timing.after_window_us >= c.cycle.period_us &&
             timing.load <= k.max_bus_load) {  // else the bus-load error below says it
    // The SDO request goes out after the window and its answer follows: both must be on the
    // wire before the next SYNC.
    diag.error(locate(doc, {k.response_timeout_us != 0 ? "canio" : "cycle",
                            k.response_timeout_us != 0 ? "response_timeout_us" : "period_us"}),
               k.response_timeout_us != 0 ? "canio.response_timeout_us" : "cycle.period_us",
               "the response window (" + std::to_string(timing.window_us) + " µs)" +
                   (timing.after_window_us > 0 ? " and the SDO request and answer after it (" +
                                                     std::to_string(timing.after_window_us) + " µs)"
                                               : std::string()) +
                   " must fit into cycle.period_us (" + std::to_string(c.cycle.period_us) +
                   "): use period_us > " +
                   std::to_string(timing.window_us + timing.after_window_us) +
                   ", fewer modules or a higher bit rate");
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

  // An identity is read by SDO while the node's modules are configured: a node no axis uses is
  // never configured, and without SDO nothing can be read.
  const YAML::Node canio_nodes =
      doc.IsMap() && doc["canio"].IsMap() ? doc["canio"]["nodes"] : YAML::Node();
  for (std::size_t j = 0; j < k.nodes.size(); ++j) {
    const CanioNodeOptions& n = k.nodes[j];
    if (!n.identity.any()) continue;
    const std::string key = "canio.nodes[" + std::to_string(j) + "]";
    const Loc at = canio_nodes.IsSequence() && j < canio_nodes.size() && canio_nodes[j].IsMap()
                       ? locate(canio_nodes[j], {"node"})
                       : locate(doc, {"canio", "nodes"});
    const bool used = std::any_of(c.axes.begin(), c.axes.end(),
                                  [&](const AxisConfig& a) { return a.node == n.node; });
    if (!used) {
      diag.error(at, key + ".node",
                 "node " + std::to_string(n.node) +
                     " has an expected identity but no axis uses it: its identity would never be "
                     "read (the node is checked while its modules are configured)");
    } else if (k.acyclic == CanAcyclicTransport::None) {
      diag.error(at, key,
                 "node " + std::to_string(n.node) +
                     ": an expected identity (0x1000 / 0x1018) is read by SDO, but "
                     "canio.acyclic.transport is none");
    }
  }
  // Bits on the wire per cycle (worst-case stuffing) plus the daemon's own acyclic traffic
  // against the share of the period the bus may carry.
  if (k.bitrate > 0 && timing.load > k.max_bus_load) {
    // The shortest period within the budget (the load falls with the period; the SDO share is
    // per max(period, sdo_interval_us)).
    uint32_t lo = c.cycle.period_us, hi = 100'000'000;
    while (lo + 1 < hi) {
      const uint32_t mid = lo + (hi - lo) / 2;
      (canio_timing(k, c.axes.size(), mid).load <= k.max_bus_load ? hi : lo) = mid;
    }
    // ... and in which the response window and the SDO answer after it fit.
    const uint32_t need_us = std::max(hi, timing.window_us + timing.after_window_us + 1);
    std::ostringstream pct;
    pct << std::fixed << std::setprecision(0) << timing.load * 100.0;
    std::ostringstream max_pct;
    max_pct << std::fixed << std::setprecision(0) << k.max_bus_load * 100.0;
    const uint32_t frames = static_cast<uint32_t>(3 * c.axes.size()) + (k.sync_enabled ? 1u : 0u);
    diag.error(
        locate(doc, {"cycle", "period_us"}), "cycle.period_us",
        std::to_string(c.cycle.period_us) + " µs loads the CAN-I/O bus to " + pct.str() +
            " %, above canio.max_bus_load " + max_pct.str() + " %: " + std::to_string(frames) +
            " frames a cycle (" + std::to_string(c.axes.size()) + " module(s) × 3" +
            (k.sync_enabled ? " + SYNC" : "") + ") take " +
            std::to_string((timing.cyclic_ns + 999) / 1000) + " µs with worst-case stuffing at " +
            std::to_string(k.bitrate) + " bit/s" +
            (timing.acyclic_ns > 0 ? ", the SDO transfers' share " +
                                         std::to_string((timing.acyclic_ns + 999) / 1000) + " µs"
                                   : std::string()) +
            "; use period_us ≥ " + std::to_string(need_us) +
            ", fewer modules or a higher bit rate");
  }
}

void dump_canio(std::ostream& o, const CanioBusConfig& c) {
  o << "canio:\n"
    << "  interface: \"" << c.interface << "\"\n"
    << "  bitrate: " << c.bitrate << "\n"
    << "  response_timeout_us: " << c.response_timeout_us
    << (c.response_timeout_us == 0 ? "  # derived from the bit budget\n" : "\n")
    << "  node_reaction_us: " << c.node_reaction_us << "\n"
    << "  max_bus_load: " << c.max_bus_load << "\n"
    << "  verify: " << (c.verify == CanVerify::None ? "none" : "readback") << "\n"
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
    << "    sdo_timeout_ms: " << c.sdo_timeout_ms << "\n"
    << "    sdo_interval_us: " << c.sdo_interval_us << "\n"
    << "    info_interval_ms: " << c.info_interval_ms << "\n";
  if (!c.sdo_overrides.empty()) {
    o << "    sdo_objects:\n";
    for (const auto& [reg, obj] : c.sdo_overrides)
      o << "      - {register: " << reg << ", index: 0x" << std::hex << std::uppercase << obj.first
        << ", subindex: 0x" << int(obj.second) << std::dec << "}\n";
  }
  o << "  nmt: " << (c.nmt == CanNmt::None ? "none" : "start") << "\n";
  if (!c.nodes.empty()) {
    o << "  nodes:\n";
    for (const CanioNodeOptions& n : c.nodes) {
      o << "    - {node: " << int(n.node) << ", heartbeat_ms: " << n.heartbeat_ms
        << ", heartbeat_timeout_ms: " << n.heartbeat_timeout_ms;
      const auto hex = [&](const char* key, const std::optional<uint32_t>& v) {
        if (v)
          o << ", " << key << ": 0x" << std::hex << std::uppercase << std::setw(8)
            << std::setfill('0') << *v << std::dec << std::setfill(' ');
      };
      hex("device_type", n.identity.device_type);
      hex("vendor_id", n.identity.vendor_id);
      hex("product_code", n.identity.product_code);
      hex("revision_no", n.identity.revision_no);
      hex("serial_no", n.identity.serial_no);
      o << "}\n";
    }
  }
  o << "  stall_limit: " << c.stall_limit << (c.stall_limit == 0 ? "  # derived\n" : "\n")
    << "  allow_manual_restart: " << (c.allow_manual_restart ? "true" : "false") << "\n";
  if (!c.virtual_bus.empty()) o << "  virtual_bus: \"" << c.virtual_bus << "\"\n";
}

}  // namespace ds1928::config_detail
