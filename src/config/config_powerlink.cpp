// The `powerlink` section: nodes, thresholds, NMT timing, SDO overrides (docs/powerlink.md).
#include "config/config_powerlink.hpp"

#include <algorithm>
#include <string>

namespace ds1928::config_detail {
namespace {

// POWERLINK process image of each CN (docs/powerlink.md §Process image): a module sits at its
// pres_offset/preq_offset or at its offset in the all-default packed layout (slot order). Two
// blocks must not share a byte and each must end within 1490 bytes and the node's configured
// pres_size/preq_size. The MN checks the same at start (make_layout()); here the message can
// point at the file.
void check_process_image(Diagnostics& diag, const DaemonConfig& c,
                         const std::vector<AxisSite>& axes) {
  struct Block {
    size_t axis;
    size_t start[2];  // PRes, PReq
    size_t size[2];
  };
  static constexpr const char* kFrame[2] = {"PRes", "PReq"};
  static constexpr const char* kKey[2] = {"pres_offset", "preq_offset"};
  std::map<uint8_t, std::vector<size_t>> by_node;
  for (size_t i = 0; i < axes.size() && i < c.axes.size(); ++i)
    by_node[c.axes[i].node].push_back(i);
  for (auto& [node, members] : by_node) {
    std::stable_sort(members.begin(), members.end(),
                     [&](size_t x, size_t y) { return c.axes[x].slot < c.axes[y].slot; });
    const PowerlinkNodeConfig* nc = nullptr;
    for (const auto& n : c.powerlink.nodes)
      if (n.node_id == node) nc = &n;
    std::vector<Block> blocks;
    size_t packed[2] = {0, 0};
    for (size_t i : members) {
      const AxisConfig& a = c.axes[i];
      const std::optional<uint16_t> offset[2] = {a.pres_offset, a.preq_offset};
      Block b{i, {}, {16u + a.module.input_mtu, 2u + a.module.output_mtu}};
      for (int f = 0; f < 2; ++f) {
        b.start[f] = offset[f] ? *offset[f] : packed[f];
        packed[f] += b.size[f];
      }
      blocks.push_back(b);
    }
    for (size_t k = 0; k < blocks.size(); ++k) {
      const Block& b = blocks[k];
      const AxisConfig& a = c.axes[b.axis];
      const std::optional<uint16_t> offset[2] = {a.pres_offset, a.preq_offset};
      const std::optional<uint16_t> limit[2] = {nc ? nc->pres_size : std::nullopt,
                                                nc ? nc->preq_size : std::nullopt};
      for (int f = 0; f < 2; ++f) {
        const Loc at = offset[f]
                           ? (f == 0 ? axes[b.axis].pres_offset_at : axes[b.axis].preq_offset_at)
                           : axes[b.axis].at;
        const std::string path = axes[b.axis].path + (offset[f] ? std::string(".") + kKey[f] : "");
        const std::string what = std::string(kFrame[f]) + " block of node " + std::to_string(node) +
                                 " slot " + std::to_string(a.slot) + " (bytes " +
                                 std::to_string(b.start[f]) + ".." +
                                 std::to_string(b.start[f] + b.size[f] - 1) + ")";
        const size_t end = b.start[f] + b.size[f];
        const size_t max = limit[f] ? *limit[f] : 1490;
        if (end > max) {
          diag.error(at, path,
                     what + " ends past the " + kFrame[f] + " payload of " + std::to_string(max) +
                         " bytes" +
                         (limit[f] ? std::string(" (powerlink.nodes ") +
                                         (f == 0 ? "pres_size" : "preq_size") + ")"
                                   : std::string()));
        }
        for (size_t j = 0; j < k; ++j) {
          const Block& o = blocks[j];
          if (!(b.start[f] < o.start[f] + o.size[f] && o.start[f] < end)) continue;
          // Report at the moved block: a default place is not what the user wrote.
          const bool here =
              offset[f] || !(f == 0 ? c.axes[o.axis].pres_offset : c.axes[o.axis].preq_offset);
          const Block& r = here ? b : o;  // reported
          const Block& x = here ? o : b;  // the one it hits
          const std::string key = offset[f] || !here ? std::string(".") + kKey[f] : "";
          const Loc r_at =
              key.empty() ? axes[r.axis].at
                          : (f == 0 ? axes[r.axis].pres_offset_at : axes[r.axis].preq_offset_at);
          auto bytes = [f](const Block& blk) {
            return "(bytes " + std::to_string(blk.start[f]) + ".." +
                   std::to_string(blk.start[f] + blk.size[f] - 1) + ")";
          };
          diag.error(r_at, axes[r.axis].path + key,
                     std::string(kFrame[f]) + " block of node " + std::to_string(node) + " slot " +
                         std::to_string(c.axes[r.axis].slot) + " " + bytes(r) + " overlaps slot " +
                         std::to_string(c.axes[x.axis].slot) + " " + bytes(x) + " of axes[" +
                         std::to_string(x.axis) + "] (" + where(axes[x.axis].at) + ")");
        }
      }
    }
  }
}

}  // namespace

void parse_powerlink(Section s, PowerlinkBusConfig& p, PowerlinkSites& sites) {
  if (s.text("interface", p.interface, 15) && !p.interface.empty() &&
      !valid_interface_name(p.interface)) {
    s.error("interface", "'" + p.interface + "' is not a network interface name");
  }
  for (auto& item : s.list("nodes")) {
    Section n(s.diag(), item.node, item.path, item.at);
    PowerlinkNodeConfig node;
    if (!n.has("node_id")) {
      s.diag().error(item.at, n.child("node_id"), "missing required key (CN node id 1..239)");
    }
    const bool have_id = n.integer("node_id", node.node_id, 1, 239, "(POWERLINK CN)");
    n.optional_integer("vendor_id", node.vendor_id, 0, kU32);
    n.optional_integer("product_code", node.product_code, 0, kU32);
    n.optional_integer("device_type", node.device_type, 0, kU32);
    n.integer("pres_timeout_us", node.pres_timeout_us, 1, 100000, "µs");
    sites.pres_timeout_at.push_back(n.value_at("pres_timeout_us"));
    n.boolean("mandatory", node.mandatory);
    n.integer("multiplex", node.multiplex, 0, 255, "(0 = every cycle)");
    n.optional_integer("preq_size", node.preq_size, 0, 1490);
    n.optional_integer("pres_size", node.pres_size, 0, 1490);
    if (have_id) {
      if (const auto prev = sites.nodes.find(node.node_id); prev != sites.nodes.end()) {
        n.error("node_id", "node " + std::to_string(node.node_id) + " is listed twice (also at " +
                               where(prev->second) + ")");
      } else {
        sites.nodes.emplace(node.node_id, n.value_at("node_id"));
      }
    }
    n.finish();
    p.nodes.push_back(node);
  }
  Section t = s.section("thresholds");
  t.integer("loss_of_pres", p.thresholds.loss_of_pres, 0, kU32, "(0 = disabled)");
  t.integer("cycle_time_exceeded", p.thresholds.cycle_time_exceeded, 0, kU32, "(0 = disabled)");
  t.integer("late_pres", p.thresholds.late_pres, 0, kU32, "(0 = disabled)");
  t.finish();
  Section nmt = s.section("nmt");
  nmt.integer("pre_op1_timeout_ms", p.nmt.pre_op1_timeout_ms, 1, 600000, "ms");
  nmt.integer("boot_step_timeout_ms", p.nmt.boot_step_timeout_ms, 1, 600000, "ms");
  nmt.integer("reset_wait_ms", p.nmt.reset_wait_ms, 0, 600000, "ms");
  nmt.integer("status_request_every", p.nmt.status_request_every, 1, 10000, "cycles");
  nmt.finish();
  s.integer("async_timeout_us", p.async_timeout_us, 1, 100000, "µs");
  s.integer("sdo_timeout_ms", p.sdo_timeout_ms, 1, 60000, "ms");
  s.integer("nettime_offset_us", p.nettime_offset_us, std::numeric_limits<int64_t>::min(),
            std::numeric_limits<int64_t>::max());
  std::map<uint16_t, Loc> overridden;
  for (auto& item : s.list("sdo_overrides")) {
    Section o(s.diag(), item.node, item.path, item.at);
    uint16_t reg = 0;
    uint16_t index = 0;
    uint8_t subindex = 0;
    for (const char* required : {"register", "index"}) {
      if (!o.has(required)) {
        s.diag().error(item.at, o.child(required), "missing required key");
      }
    }
    const bool have_reg = o.integer("register", reg, 0, kU16, "(X20DS1928 register number)");
    const bool have_index = o.integer("index", index, 1, kU16);
    o.integer("subindex", subindex, 0, kU8);
    if (have_reg && have_index) {
      if (const auto prev = overridden.find(reg); prev != overridden.end()) {
        o.error("register", "register " + std::to_string(reg) + " is overridden twice (also at " +
                                where(prev->second) + ")");
      } else {
        overridden.emplace(reg, o.value_at("register"));
        p.sdo_overrides[reg] = {index, subindex};
      }
    }
    o.finish();
  }
  s.finish();
}

void check_powerlink(Diagnostics& diag, const DaemonConfig& c, const std::vector<AxisSite>& axes,
                     const PowerlinkSites& sites) {
  check_process_image(diag, c, axes);
  for (size_t i = 0; i < c.powerlink.nodes.size() && i < sites.pres_timeout_at.size(); ++i) {
    const auto& n = c.powerlink.nodes[i];
    if (n.pres_timeout_us >= c.cycle.period_us) {
      diag.error(
          sites.pres_timeout_at[i], "powerlink.nodes[" + std::to_string(i) + "].pres_timeout_us",
          "pres_timeout_us (" + std::to_string(n.pres_timeout_us) +
              ") must be less than cycle.period_us (" + std::to_string(c.cycle.period_us) + ")");
    }
  }
}

void dump_powerlink(std::ostream& o, const PowerlinkBusConfig& p) {
  o << "powerlink:\n"
    << "  interface: " << quote(p.interface) << "\n"
    << "  nodes:" << (p.nodes.empty() ? " []" : "") << "\n";
  const auto opt = [](const auto& v) { return v ? hex(*v) : std::string(); };
  const auto opt_dec = [](const auto& v) { return v ? std::to_string(*v) : std::string(); };
  for (const auto& n : p.nodes) {
    o << "    - node_id: " << +n.node_id << "\n"
      << "      vendor_id: " << opt(n.vendor_id) << "\n"
      << "      product_code: " << opt(n.product_code) << "\n"
      << "      device_type: " << opt(n.device_type) << "\n"
      << "      pres_timeout_us: " << n.pres_timeout_us << "\n"
      << "      mandatory: " << yes(n.mandatory) << "\n"
      << "      multiplex: " << n.multiplex << "\n"
      << "      preq_size: " << opt_dec(n.preq_size) << "\n"
      << "      pres_size: " << opt_dec(n.pres_size) << "\n";
  }
  o << "  thresholds:\n"
    << "    loss_of_pres: " << p.thresholds.loss_of_pres << "\n"
    << "    cycle_time_exceeded: " << p.thresholds.cycle_time_exceeded << "\n"
    << "    late_pres: " << p.thresholds.late_pres << "\n"
    << "  nmt:\n"
    << "    pre_op1_timeout_ms: " << p.nmt.pre_op1_timeout_ms << "\n"
    << "    boot_step_timeout_ms: " << p.nmt.boot_step_timeout_ms << "\n"
    << "    reset_wait_ms: " << p.nmt.reset_wait_ms << "\n"
    << "    status_request_every: " << p.nmt.status_request_every << "\n"
    << "  async_timeout_us: " << p.async_timeout_us << "\n"
    << "  sdo_timeout_ms: " << p.sdo_timeout_ms << "\n"
    << "  nettime_offset_us: " << p.nettime_offset_us << "\n"
    << "  sdo_overrides:" << (p.sdo_overrides.empty() ? " []" : "") << "\n";
  for (const auto& [reg, target] : p.sdo_overrides) {
    o << "    - {register: " << reg << ", index: " << hex(target.first)
      << ", subindex: " << hex(target.second) << "}\n";
  }
}

}  // namespace ds1928::config_detail
