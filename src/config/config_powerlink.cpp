// The `powerlink` section: nodes, thresholds, NMT timing, SDO overrides (docs/powerlink.md).
#include "config/config_powerlink.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <tuple>

#include "config/config_powerlink_cdc.hpp"
#include "config/config_sdo_objects.hpp"
#include "powerlink/concise_dcf.hpp"
#include "powerlink/cycle_budget.hpp"

namespace ds1928::config_detail {
namespace {

// The node's modules sit where the PDO mapping its objects write says (not packed).
bool image_from_mapping(const PowerlinkNodeConfig& n) {
  if (n.layout == ImageLayout::kPacked) return false;
  if (n.layout == ImageLayout::kMapping) return true;
  std::vector<powerlink::CdcEntry> written;
  for (const auto& w : n.object_writes) written.push_back({w.index, w.subindex, w.data});
  const auto* count = powerlink::find_cdc_entry(written, powerlink::obj::kTxPdoMapping, 0);
  const auto v = count ? count->as_unsigned() : std::nullopt;
  return v && *v > 0;
}

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
    // From the PDO mapping: the MN binds and checks it at start, naming entry, slot and register.
    if (nc && image_from_mapping(*nc)) continue;
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

// A concise DCF file, read and decoded; on failure an error at `key` and nullopt.
std::optional<std::vector<powerlink::CdcEntry>> load_cdc(Section& s, std::string_view key,
                                                         std::string& path,
                                                         const std::filesystem::path& base_dir) {
  std::filesystem::path file(path);
  if (file.is_relative()) file = base_dir / file;
  file = file.lexically_normal();
  if (const std::string why = unusable_file(file); !why.empty()) {
    s.error(key, why);
    return std::nullopt;
  }
  std::ifstream in(file, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  if (!in.good() && !in.eof()) {
    s.error(key, "cannot read " + file.string());
    return std::nullopt;
  }
  path = file.string();
  auto decoded = powerlink::decode_cdc(bytes);
  if (!decoded.ok()) {
    s.error(key, file.string() + " is not a valid concise DCF: " + decoded.error->message +
                     " (byte " + std::to_string(decoded.error->offset) + ")");
    return std::nullopt;
  }
  return std::move(decoded.entries);
}

// Hex bytes of a domain value: "01 02 0a", "01020A" or "0x01,0x02".
std::optional<std::vector<uint8_t>> parse_hex_bytes(std::string_view text) {
  std::vector<uint8_t> out;
  std::string digits;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == ' ' || c == ',' || c == ':' || c == '\t') {
      if (digits.size() % 2 != 0) return std::nullopt;
      continue;
    }
    if (c == '0' && i + 1 < text.size() && (text[i + 1] == 'x' || text[i + 1] == 'X') &&
        digits.size() % 2 == 0) {
      ++i;
      continue;
    }
    if (!std::isxdigit(static_cast<unsigned char>(c))) return std::nullopt;
    digits += c;
  }
  if (digits.size() % 2 != 0) return std::nullopt;
  for (std::size_t i = 0; i < digits.size(); i += 2)
    out.push_back(static_cast<uint8_t>(std::stoul(digits.substr(i, 2), nullptr, 16)));
  return out;
}

// One `sdo_writes` item: index, subindex and exactly one typed value.
void parse_sdo_write(Section o, std::vector<CnObjectWrite>& out) {
  CnObjectWrite w;
  if (!o.has("index")) o.diag().error(o.at(), o.child("index"), "missing required key");
  const bool have_index = o.integer("index", w.index, 1, kU16);
  o.integer("subindex", w.subindex, 0, kU8);
  struct Type {
    const char* key;
    std::size_t size;
    int64_t lo, hi;
  };
  static constexpr Type kTypes[] = {
      {"u8", 1, 0, 0xFF},
      {"u16", 2, 0, 0xFFFF},
      {"u32", 4, 0, 0xFFFFFFFF},
      {"u64", 8, 0, std::numeric_limits<int64_t>::max()},
      {"i8", 1, -128, 127},
      {"i16", 2, -32768, 32767},
      {"i32", 4, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()},
      {"i64", 8, std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::max()},
  };
  std::vector<std::string> given;
  for (const Type& t : kTypes) {
    if (!o.has(t.key)) {
      (void)o.find(t.key);  // known key
      continue;
    }
    given.emplace_back(t.key);
    int64_t v = 0;
    if (o.integer(t.key, v, t.lo, t.hi)) {
      w.data.clear();
      for (std::size_t i = 0; i < t.size; ++i)
        w.data.push_back(static_cast<uint8_t>(static_cast<uint64_t>(v) >> (8 * i)));
    }
  }
  if (o.has("domain")) {
    given.emplace_back("domain");
    std::string text;
    if (o.text("domain", text, 4096)) {
      const auto bytes = parse_hex_bytes(text);
      if (!bytes || bytes->empty()) {
        o.error("domain", "'" + text + "' is not a list of hex bytes such as \"01 02 0a\"");
      } else {
        w.data = *bytes;
      }
    }
  } else {
    (void)o.find("domain");
  }
  if (given.empty()) {
    o.diag().error(o.at(), o.path(),
                   "missing the value: give exactly one of u8, u16, u32, u64, i8, i16, i32, i64, "
                   "domain");
  } else if (given.size() > 1) {
    o.diag().error(o.at(), o.path(), "more than one value given (" + join(given) + "); give one");
  }
  o.finish();
  if (have_index && given.size() == 1 && !w.data.empty()) out.push_back(std::move(w));
}

// The bus controller's object scheme (docs/powerlink.md §Process image from the PDO mapping).
void parse_object_scheme(Section os, PdoObjectScheme& scheme) {
  os.integer("input_index", scheme.input_index, 0x2000, 0xFFEF, "(slot s's inputs: index + s)");
  os.integer("output_index", scheme.output_index, 0x2000, 0xFFEF, "(slot s's outputs: index + s)");
  os.finish();
}

}  // namespace

void parse_powerlink(Section s, PowerlinkBusConfig& p, PowerlinkSites& sites,
                     const std::filesystem::path& base_dir) {
  if (!s.text("interface", p.interface, 15)) {
    sites.interface_refused = s.has("interface");
  } else if (!p.interface.empty() && !valid_interface_name(p.interface)) {
    s.error("interface", "'" + p.interface + "' is not a network interface name");
  }
  parse_object_scheme(s.section("object_scheme"), p.object_scheme);
  s.boolean("allow_shared_interface", p.allow_shared_interface);
  std::vector<powerlink::CdcEntry> mn_cdc;
  if (s.text("cdc", p.cdc) && !p.cdc.empty()) {
    if (auto entries = load_cdc(s, "cdc", p.cdc, base_dir)) mn_cdc = std::move(*entries);
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
    n.optional_integer("revision_no", node.revision_no, 0, kU32);
    n.optional_integer("serial_no", node.serial_no, 0, kU32);
    n.optional_integer("expected_conf_date", node.expected_conf_date, 0, kU32);
    n.optional_integer("expected_conf_time", node.expected_conf_time, 0, kU32);
    bool own_cdc = false;
    if (n.text("cdc", node.cdc) && !node.cdc.empty()) {
      own_cdc = true;
      if (auto entries = load_cdc(n, "cdc", node.cdc, base_dir)) {
        for (auto& e : *entries)
          node.object_writes.push_back({e.index, e.subindex, std::move(e.data), true});
      }
    }
    n.boolean("cycle_objects", node.cycle_objects);
    n.integer("pres_timeout_us", node.pres_timeout_us, 1, 100000, "µs");
    sites.pres_timeout_at.push_back(n.value_at("pres_timeout_us"));
    n.integer("pres_latency_us", node.pres_latency_us, 0, 100000, "µs");
    sites.pres_latency_at.push_back(n.has("pres_latency_us")
                                        ? std::optional<Loc>(n.value_at("pres_latency_us"))
                                        : std::nullopt);
    n.optional_integer("loss_of_pres_threshold", node.loss_of_pres_threshold, 0, kU32);
    n.boolean("mandatory", node.mandatory);
    if (n.has("multiplex")) {
      uint32_t factor = 0;  // read, so the key is known; refused with the way forward
      n.integer("multiplex", factor, 0, 255);
      n.error("multiplex",
              "the per-node multiplex factor is gone: DS 301 has one multiplexed cycle for the "
              "network; give powerlink.multiplex_cycles (NMT_CycleTiming MultiplCycleCnt) and mark "
              "this "
              "node `multiplexed: true` (its slot: multiplex_slot, else the MN assigns one)");
    }
    n.boolean("multiplexed", node.multiplexed);
    n.optional_integer("multiplex_slot", node.multiplex_slot, 1, 255);
    if (node.multiplex_slot) {
      if (n.has("multiplexed") && !node.multiplexed)
        n.error("multiplex_slot", "a slot for a node marked `multiplexed: false`");
      node.multiplexed = true;
    }
    n.boolean("prc", node.prc);
    n.optional_integer("preq_size", node.preq_size, 0, 1490);
    n.optional_integer("pres_size", node.pres_size, 0, 1490);
    n.choice("layout", node.layout,
             {{"auto", ImageLayout::kAuto},
              {"packed", ImageLayout::kPacked},
              {"mapping", ImageLayout::kMapping}});
    if (n.has("object_scheme")) {
      PdoObjectScheme scheme = p.object_scheme;
      parse_object_scheme(n.section("object_scheme"), scheme);
      node.object_scheme = scheme;
    }
    for (auto& w : n.list("sdo_writes"))
      parse_sdo_write(Section(n.diag(), w.node, w.path, w.at), node.object_writes);
    if (have_id && !mn_cdc.empty())
      apply_mn_cdc(n, node, p.nodes.size(), mn_cdc, own_cdc, p.sources);
    if (node.multiplexed)
      sites.multiplexed.emplace_back(
          n.value_at(node.multiplex_slot ? "multiplex_slot" : "multiplexed"), p.nodes.size());
    // Sizes the written objects define (NMT_CycleTiming /4,5 or the PDO mappings), unless given.
    std::vector<powerlink::CdcEntry> written;
    for (const auto& w : node.object_writes) written.push_back({w.index, w.subindex, w.data});
    const auto sizes = powerlink::image_sizes_from_objects(written);
    for (auto [size, from, key] : {std::tuple{&node.preq_size, sizes.preq_size, "preq_size"},
                                   std::tuple{&node.pres_size, sizes.pres_size, "pres_size"}}) {
      if (*size || !from) continue;
      if (*from > 1490) {
        n.error("node_id", std::string("the objects written to this node give a ") + key + " of " +
                               std::to_string(*from) + " bytes; at most 1490 are allowed");
      } else {
        *size = from;
      }
    }
    if (node.layout == ImageLayout::kMapping && node.prc) {
      const auto* count = powerlink::find_cdc_entry(written, powerlink::obj::kTxPdoMapping, 0);
      const auto v = count ? count->as_unsigned() : std::nullopt;
      if (!v || *v == 0)
        n.error("layout",
                "layout mapping on a PollResponse Chaining node (prc) needs the node's TPDO "
                "mapping (PDO_TxMappParam) among the objects written to it (its cdc or "
                "sdo_writes): a chained node's image cannot change at boot");
    }
    if (node.prc && node.multiplexed) {
      n.error(node.multiplex_slot ? "multiplex_slot" : "multiplexed",
              "a PollResponse Chaining node (prc) answers the PResMN every cycle: "
              "PRC has no multiplexed slots; remove multiplexed/multiplex_slot or prc");
    }
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
  t.optional_integer("loss_of_pres", p.thresholds.loss_of_pres, 0, kU32);
  t.integer("cycle_time_exceeded", p.thresholds.cycle_time_exceeded, 0, kU32, "(0 = disabled)");
  t.integer("late_pres", p.thresholds.late_pres, 0, kU32, "(0 = disabled)");
  t.finish();
  Section nmt = s.section("nmt");
  nmt.integer("wait_not_active_ms", p.nmt.wait_not_active_ms, 0, 600000, "ms");
  nmt.integer("pre_op1_timeout_ms", p.nmt.pre_op1_timeout_ms, 1, 600000, "ms");
  nmt.integer("boot_step_timeout_ms", p.nmt.boot_step_timeout_ms, 1, 600000, "ms");
  nmt.integer("reset_wait_ms", p.nmt.reset_wait_ms, 0, 600000, "ms");
  nmt.integer("status_request_every", p.nmt.status_request_every, 1, 10000, "cycles");
  nmt.finish();
  // AsyncSlotTimeout by its standard name; async_timeout_us is the older spelling.
  if (s.has("async_slot_timeout_us") && s.has("async_timeout_us"))
    s.error("async_timeout_us", "give either async_slot_timeout_us or async_timeout_us, not both");
  s.integer("async_slot_timeout_us", p.async_timeout_us, 1, 100000, "µs");
  s.integer("async_timeout_us", p.async_timeout_us, 1, 100000, "µs");
  s.integer("wait_soc_preq_us", p.wait_soc_preq_us, 0, 100000, "µs");
  s.integer("async_mtu", p.async_mtu, 300, 1500, "bytes (AsyncMTU, DS 301)");
  if (!mn_cdc.empty()) apply_mn_cdc_network(s, t, nmt, p, mn_cdc);
  sites.mn_cdc = mn_cdc;
  // PResMN payload: the key, else the MN's CDC (NMT_CycleTiming_REC.PResActPayloadLimit_U16).
  if (!s.has("pres_mn_size") && !mn_cdc.empty())
    if (const auto* e = powerlink::find_cdc_entry(mn_cdc, powerlink::obj::kCycleTiming,
                                                  powerlink::obj::kCycleTimingPResActPayload);
        e && e->as_unsigned())
      p.pres_mn_size = static_cast<uint16_t>(std::min<uint64_t>(*e->as_unsigned(), 1490));
  // MultiplCycleCnt: the key, else the MN's CDC (NMT_CycleTiming_REC.MultiplCycleCnt_U8).
  if (!s.has("multiplex_cycles") && !mn_cdc.empty())
    if (const auto* e = powerlink::find_cdc_entry(mn_cdc, powerlink::obj::kCycleTiming,
                                                  powerlink::obj::kCycleTimingMultiplCycleCnt);
        e && e->as_unsigned())
      p.multiplex_cycles = static_cast<uint8_t>(std::min<uint64_t>(*e->as_unsigned(), 255));
  s.integer("multiplex_cycles", p.multiplex_cycles, 0, 255, "(0 = no multiplexing)");
  for (const auto& [at, i] : sites.multiplexed) {
    const PowerlinkNodeConfig& node = p.nodes[i];
    const std::string key = "nodes[" + std::to_string(i) + "]." +
                            (node.multiplex_slot ? "multiplex_slot" : "multiplexed");
    if (p.multiplex_cycles < 2) {
      s.diag().error(at, "powerlink." + key,
                     "node " + std::to_string(node.node_id) +
                         " is multiplexed, but powerlink.multiplex_cycles (MultiplCycleCnt) is " +
                         std::to_string(p.multiplex_cycles) + ": give at least 2");
    } else if (node.multiplex_slot && *node.multiplex_slot > p.multiplex_cycles) {
      s.diag().error(at, "powerlink." + key,
                     "slot " + std::to_string(*node.multiplex_slot) + " of node " +
                         std::to_string(node.node_id) + " is outside the multiplexed cycle of " +
                         std::to_string(p.multiplex_cycles) + " (powerlink.multiplex_cycles): 1.." +
                         std::to_string(p.multiplex_cycles));
    }
  }
  // Slots the configuration leaves open: assigned here as the MN would (--print-config shows
  // them), so the budget and the MN agree.
  if (p.multiplex_cycles > 1) {
    std::vector<powerlink::MultiplexNode> mux;
    for (const auto& node : p.nodes)
      if (node.multiplexed) mux.push_back({node.node_id, node.multiplex_slot.value_or(0)});
    powerlink::assign_multiplex_slots(mux, p.multiplex_cycles);
    for (auto& node : p.nodes)
      for (const auto& m : mux)
        if (node.multiplexed && m.node_id == node.node_id) node.multiplex_slot = m.slot;
  }
  s.integer("pres_mn_size", p.pres_mn_size, 0, 1490, "bytes");
  if (s.has("pres_mn_size")) sites.pres_mn_size_at = s.value_at("pres_mn_size");
  s.choice("rx_wait", p.rx_wait,
           {{"block", RxWait::Block}, {"spin", RxWait::Spin}, {"busy_poll", RxWait::BusyPoll}});
  s.integer("rx_spin_us", p.rx_spin_us, 0, 100000, "µs");
  sites.async_timeout_at = s.has("async_timeout_us") ? s.value_at("async_timeout_us")
                                                     : s.value_at("async_slot_timeout_us");
  s.integer("sdo_timeout_ms", p.sdo_timeout_ms, 1, 60000, "ms");
  s.integer("nettime_offset_us", p.nettime_offset_us, std::numeric_limits<int64_t>::min(),
            std::numeric_limits<int64_t>::max());
  parse_sdo_objects(s, "sdo_overrides", p.sdo_overrides);
  s.finish();
}

// The outputs of a chained node take its PReq image's bytes in the PResMN (docs/powerlink.md
// §PollResponse Chaining): the end of its packed blocks (or offsets), or of its written RPDO
// mapping.
std::size_t output_image_size(const DaemonConfig& c, const PowerlinkNodeConfig& n) {
  if (image_from_mapping(n)) {
    std::vector<powerlink::CdcEntry> written;
    for (const auto& w : n.object_writes) written.push_back({w.index, w.subindex, w.data});
    const auto* count = powerlink::find_cdc_entry(written, powerlink::obj::kRxPdoMapping, 0);
    const auto n_entries = count ? count->as_unsigned().value_or(0) : 0;
    std::size_t end = 0;
    for (uint64_t k = 1; k <= n_entries && k <= 254; ++k) {
      const auto* e = powerlink::find_cdc_entry(written, powerlink::obj::kRxPdoMapping,
                                                static_cast<uint8_t>(k));
      if (!e || !e->as_unsigned()) continue;
      const auto m = powerlink::PdoMapEntry::from_u64(*e->as_unsigned());
      end = std::max<std::size_t>(end, (std::size_t{m.offset_bits} + m.length_bits + 7u) / 8u);
    }
    return end;
  }
  std::vector<const AxisConfig*> members;
  for (const AxisConfig& a : c.axes)
    if (a.node == n.node_id) members.push_back(&a);
  std::stable_sort(members.begin(), members.end(),
                   [](const AxisConfig* x, const AxisConfig* y) { return x->slot < y->slot; });
  std::size_t packed = 0, end = 0;
  for (const AxisConfig* a : members) {
    const std::size_t size = 2u + a->module.output_mtu;
    end = std::max(end, a->preq_offset.value_or(static_cast<uint16_t>(packed)) + size);
    packed += size;
  }
  return end;
}

void check_powerlink(const BusDocument& d) {
  Diagnostics& diag = d.diag;
  const DaemonConfig& c = d.config;
  const std::vector<AxisSite>& axes = d.axes;
  const PowerlinkSites& sites = d.powerlink;
  if (d.section_present) {
    if (c.powerlink.interface.empty() && !sites.interface_refused) {
      diag.error(d.section_at, "powerlink.interface",
                 "missing: bus powerlink needs the network interface of the POWERLINK segment");
    }
    for (size_t i = 0; i < axes.size() && i < c.axes.size(); ++i) {
      const uint8_t node = c.axes[i].node;
      if (sites.nodes.count(node) != 0) continue;
      std::vector<std::string> listed;
      for (const auto& [id, at] : sites.nodes) listed.push_back(std::to_string(id));
      diag.error(axes[i].node_at, axes[i].path + ".node",
                 "node " + std::to_string(node) + " is not listed in powerlink.nodes (listed: " +
                     (listed.empty() ? std::string("none") : join(listed)) + ")");
    }
  }
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
  // A CN expected to answer after its timeout would lose every PRes.
  for (size_t i = 0; i < c.powerlink.nodes.size() && i < sites.pres_latency_at.size(); ++i) {
    const auto& n = c.powerlink.nodes[i];
    if (sites.pres_latency_at[i] && n.pres_latency_us >= n.pres_timeout_us) {
      diag.error(
          *sites.pres_latency_at[i], "powerlink.nodes[" + std::to_string(i) + "].pres_latency_us",
          "pres_latency_us (" + std::to_string(n.pres_latency_us) +
              ") must be less than the node's pres_timeout_us (" +
              std::to_string(n.pres_timeout_us) + "): the MN would count every PRes of it as lost");
    }
  }
  // One error per cause: a PRes timeout longer than the period is reported above already.
  const bool timeout_too_long = std::any_of(
      c.powerlink.nodes.begin(), c.powerlink.nodes.end(),
      [&](const PowerlinkNodeConfig& n) { return n.pres_timeout_us >= c.cycle.period_us; });
  if (!timeout_too_long) check_cycle_budget(diag, c, sites);
}

std::string source_comment(const PowerlinkBusConfig& p, const std::string& key) {
  const auto it = p.sources.find(key);
  return it == p.sources.end() ? std::string() : "  # " + it->second;
}

void dump_powerlink(std::ostream& o, const PowerlinkBusConfig& p) {
  o << "powerlink:\n"
    << "  interface: " << quote(p.interface) << "\n"
    << "  allow_shared_interface: " << (p.allow_shared_interface ? "true" : "false") << "\n"
    << "  cdc: " << quote(p.cdc) << "\n"
    << "  nodes:" << (p.nodes.empty() ? " []" : "") << "\n";
  const auto opt = [](const auto& v) { return v ? hex(*v) : std::string(); };
  const auto opt_dec = [](const auto& v) { return v ? std::to_string(*v) : std::string(); };
  for (std::size_t i = 0; i < p.nodes.size(); ++i) {
    const PowerlinkNodeConfig& n = p.nodes[i];
    const auto src = [&](const char* key) {
      return source_comment(p, "powerlink.nodes[" + std::to_string(i) + "]." + key);
    };
    o << "    - node_id: " << +n.node_id << "\n"
      << "      vendor_id: " << opt(n.vendor_id) << "\n"
      << "      product_code: " << opt(n.product_code) << "\n"
      << "      device_type: " << opt(n.device_type) << "\n"
      << "      revision_no: " << opt(n.revision_no) << "\n"
      << "      serial_no: " << opt(n.serial_no) << "\n"
      << "      expected_conf_date: " << opt(n.expected_conf_date) << "\n"
      << "      expected_conf_time: " << opt(n.expected_conf_time) << "\n"
      << "      cdc: " << quote(n.cdc) << "\n"
      << "      cycle_objects: " << yes(n.cycle_objects) << "\n"
      << "      pres_timeout_us: " << n.pres_timeout_us << src("pres_timeout_us") << "\n"
      << "      pres_latency_us: " << n.pres_latency_us << "\n"
      << "      mandatory: " << yes(n.mandatory) << src("mandatory") << "\n"
      << "      loss_of_pres_threshold: " << opt_dec(n.loss_of_pres_threshold)
      << src("loss_of_pres_threshold") << "\n"
      << "      multiplexed: " << yes(n.multiplexed) << "\n"
      << "      multiplex_slot: " << opt_dec(n.multiplex_slot) << "\n"
      << "      prc: " << yes(n.prc) << src("prc") << "\n"
      << "      preq_size: " << opt_dec(n.preq_size) << "\n"
      << "      pres_size: " << opt_dec(n.pres_size) << "\n"
      << "      layout: "
      << (n.layout == ImageLayout::kPacked    ? "packed"
          : n.layout == ImageLayout::kMapping ? "mapping"
                                              : "auto")
      << "\n";
    if (n.object_scheme)
      o << "      object_scheme: {input_index: " << hex(n.object_scheme->input_index)
        << ", output_index: " << hex(n.object_scheme->output_index) << "}\n";
    // The YAML writes as items; the concise DCF's objects (loaded again from `cdc` when this is
    // read back) as comments, so the dump shows everything the MN writes.
    std::size_t own = 0;
    for (const auto& w : n.object_writes) own += w.from_cdc ? 0 : 1;
    o << "      sdo_writes:" << (own == 0 ? " []" : "") << "\n";
    for (const auto& w : n.object_writes) {
      std::string bytes;
      for (const uint8_t b : w.data) {
        static constexpr char kHex[] = "0123456789abcdef";
        if (!bytes.empty()) bytes += ' ';
        bytes += kHex[b >> 4];
        bytes += kHex[b & 0xF];
      }
      o << (w.from_cdc ? "      # concise DCF: " : "        - ") << "{index: " << hex(w.index)
        << ", subindex: " << +w.subindex << ", domain: \"" << bytes << "\"}\n";
    }
  }
  o << "  thresholds:\n"
    << "    loss_of_pres: " << opt_dec(p.thresholds.loss_of_pres) << "\n"
    << "    cycle_time_exceeded: " << p.thresholds.cycle_time_exceeded
    << source_comment(p, "powerlink.thresholds.cycle_time_exceeded") << "\n"
    << "    late_pres: " << p.thresholds.late_pres << "\n"
    << "  nmt:\n"
    << "    wait_not_active_ms: " << p.nmt.wait_not_active_ms
    << source_comment(p, "powerlink.nmt.wait_not_active_ms") << "\n"
    << "    pre_op1_timeout_ms: " << p.nmt.pre_op1_timeout_ms
    << source_comment(p, "powerlink.nmt.pre_op1_timeout_ms") << "\n"
    << "    boot_step_timeout_ms: " << p.nmt.boot_step_timeout_ms << "\n"
    << "    reset_wait_ms: " << p.nmt.reset_wait_ms << "\n"
    << "    status_request_every: " << p.nmt.status_request_every << "\n"
    << "  async_slot_timeout_us: " << p.async_timeout_us
    << source_comment(p, "powerlink.async_slot_timeout_us") << "\n"
    << "  wait_soc_preq_us: " << p.wait_soc_preq_us
    << source_comment(p, "powerlink.wait_soc_preq_us") << "\n"
    << "  async_mtu: " << p.async_mtu << source_comment(p, "powerlink.async_mtu") << "\n"
    << "  multiplex_cycles: " << unsigned{p.multiplex_cycles} << "\n"
    << "  pres_mn_size: " << p.pres_mn_size << "\n"
    << "  rx_wait: "
    << (p.rx_wait == RxWait::Block  ? "block"
        : p.rx_wait == RxWait::Spin ? "spin"
                                    : "busy_poll")
    << "\n"
    << "  rx_spin_us: " << p.rx_spin_us << "\n"
    << "  sdo_timeout_ms: " << p.sdo_timeout_ms << "\n"
    << "  nettime_offset_us: " << p.nettime_offset_us << "\n"
    << "  object_scheme: {input_index: " << hex(p.object_scheme.input_index)
    << ", output_index: " << hex(p.object_scheme.output_index) << "}\n"
    << "  sdo_overrides:" << (p.sdo_overrides.empty() ? " []" : "") << "\n";
  for (const auto& [reg, target] : p.sdo_overrides) {
    o << "    - {register: " << reg << ", index: " << hex(target.first)
      << ", subindex: " << hex(target.second) << "}\n";
  }
}

}  // namespace ds1928::config_detail
