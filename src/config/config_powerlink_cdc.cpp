// The MN's concise DCF as configuration (docs/configuration.md §The MN's concise DCF).
#include "config/config_powerlink_cdc.hpp"

#include <algorithm>
#include <cstdio>
#include <limits>

#include "powerlink/standard_objects.hpp"

namespace ds1928::config_detail {
namespace {

using powerlink::find_cdc_entry;
namespace obj = powerlink::obj;
using enum MnCdcTarget;

constexpr uint64_t kU32 = std::numeric_limits<uint32_t>::max();

// The MN objects of DS 301 / openCONFIGURATOR's mnobd.cdc that ds1928d takes, one row each.
// NodeAssignment's bits, the payload limits and the multiplexed cycle are applied beside these
// (apply_mn_cdc, parse_powerlink). Ranges: what the key accepts (docs/configuration.md).
// clang-format off
constexpr MnCdcSetting kSettings[] = {
  {obj::kCycleLen, 0, false, kCyclePeriod, "cycle.period_us", 1, 1, 100, 100'000, "µs"},
  {obj::kMnCycTimeExceed, 3, false, kCycleTimeExceeded, "powerlink.thresholds.cycle_time_exceeded", 1, 0, 0, kU32, ""},
  {obj::kMnCycleTiming, 1, false, kWaitSocPreq, "powerlink.wait_soc_preq_us", 1000, 0, 0, 100'000, "ns"},
  // AsyncSlotTimeout_U32: at least 250 ns (DS 301; openPOWERLINK's object dictionary says so too).
  {obj::kMnCycleTiming, 2, false, kAsyncSlotTimeout, "powerlink.async_slot_timeout_us", 1000, 250, 1, 100'000, "ns"},
  // AsyncMTU_U16: DS 301's range, 300..1500 bytes.
  {obj::kCycleTiming, obj::kCycleTimingAsyncMtu, false, kAsyncMtu, "powerlink.async_mtu", 1, 300, 300, 1500, "bytes"},
  {obj::kMnBootTime, 1, false, kWaitNotActive, "powerlink.nmt.wait_not_active_ms", 1000, 0, 0, 600'000, "µs"},
  {obj::kMnBootTime, 2, false, kPreOp1Timeout, "powerlink.nmt.pre_op1_timeout_ms", 1000, 1, 1, 600'000, "µs"},
  {obj::kMnCnPResTimeout, 0, true, kPresTimeout, "pres_timeout_us", 1000, 1, 1, 100'000, "ns"},
  {obj::kMnCnLossPResThreshold, 0, true, kLossOfPresThreshold, "loss_of_pres_threshold", 1, 0, 0, kU32, ""},
};
// clang-format on

// "0x1F92/1 NMT_MNCNPResTimeout_AU32"
std::string named(uint16_t index, uint8_t subindex) {
  std::string s = powerlink::object_name(index, subindex);
  if (const auto n = powerlink::standard_name(index, subindex); !n.empty()) {
    s += ' ';
    s += n;
  }
  return s;
}

// The key's source when the YAML gives it or nothing does.
void note_source(std::map<std::string, std::string>& sources, const std::string& key, bool given,
                 const std::string& cdc_source) {
  sources[key] = given ? "yaml" : cdc_source.empty() ? "default" : cdc_source;
}

}  // namespace

std::span<const MnCdcSetting> mn_cdc_settings() noexcept {
  return kSettings;
}

std::optional<uint64_t> mn_cdc_value(Section& s, std::string_view key, const MnCdcSetting& row,
                                     std::span<const powerlink::CdcEntry> mn, uint8_t node,
                                     std::string& source) {
  const uint8_t sub = row.per_node ? node : row.subindex;
  const powerlink::CdcEntry* e = find_cdc_entry(mn, row.index, sub);
  if (!e) return std::nullopt;
  // At the cdc key its path names the file; elsewhere the message does.
  const std::string what = (key == "cdc" ? "" : "powerlink.cdc: ") + named(row.index, sub);
  const std::string at = " (byte " + std::to_string(e->offset) + ")";
  const auto raw = e->as_unsigned();
  if (!raw || e->data.size() > 4) {
    s.error(key, what + at + " holds " + std::to_string(e->data.size()) +
                     " bytes; DS 301 gives it 4 (UNSIGNED32)");
    return std::nullopt;
  }
  const std::string unit = row.unit.empty() ? "" : " " + std::string(row.unit);
  if (*raw < row.object_min) {
    s.error(key, what + " = " + std::to_string(*raw) + unit + at +
                     " is below DS 301's minimum of " + std::to_string(row.object_min) + unit);
    return std::nullopt;
  }
  const uint64_t value = (*raw + row.divisor - 1) / row.divisor;
  if (value < row.key_min || value > row.key_max) {
    const std::string key_unit = row.key.ends_with("_us")   ? " µs"
                                 : row.key.ends_with("_ms") ? " ms"
                                                            : "";
    s.error(key, what + " = " + std::to_string(*raw) + unit + at +
                     " is outside what ds1928d takes for " + std::string(row.key) + " (" +
                     std::to_string(row.key_min) + ".." + std::to_string(row.key_max) + key_unit +
                     ")");
    return std::nullopt;
  }
  source = "cdc " + named(row.index, sub) + " = " + std::to_string(*raw) + unit + at;
  return value;
}

void apply_mn_cdc(Section& n, PowerlinkNodeConfig& node, std::size_t i,
                  std::span<const powerlink::CdcEntry> mn, bool node_has_own_cdc,
                  std::map<std::string, std::string>& sources) {
  const uint8_t id = node.node_id;
  const std::string prefix = "powerlink.nodes[" + std::to_string(i) + "].";
  if (!node_has_own_cdc) {
    if (const auto* dcf = find_cdc_entry(mn, obj::kConciseDcfList, id)) {
      auto decoded = powerlink::decode_cdc(dcf->data);
      if (!decoded.ok()) {
        n.error("node_id",
                "powerlink.cdc: object " + powerlink::object_name(obj::kConciseDcfList, id) +
                    " (this node's concise DCF) is not valid: " + decoded.error->message);
      } else {
        for (auto& e : decoded.entries)
          node.object_writes.push_back({e.index, e.subindex, std::move(e.data), true});
      }
    }
  }
  auto value = [&](uint16_t index) -> std::optional<uint32_t> {
    const auto* e = find_cdc_entry(mn, index, id);
    const auto v = e ? e->as_unsigned() : std::nullopt;
    if (!v || *v == 0) return std::nullopt;  // 0: "do not check" in the MN's lists
    return static_cast<uint32_t>(*v);
  };
  // NMT_NodeAssignment/node: bit 3 mandatory, 8 async-only, 9 multiplexed (with
  // NMT_MultiplCycleAssign/node its slot), 14 PollResponse Chaining; the YAML's keys win.
  const auto* assignment_entry = find_cdc_entry(mn, obj::kNodeAssignment, id);
  const bool assigned = assignment_entry && assignment_entry->as_unsigned();
  const uint64_t bits = assigned ? *assignment_entry->as_unsigned() : 0;
  std::string assignment_source;
  if (assigned) {
    char hex[24];
    std::snprintf(hex, sizeof hex, "0x%08llX", static_cast<unsigned long long>(bits));
    assignment_source = "cdc " + named(obj::kNodeAssignment, id) + " = " + hex + " (byte " +
                        std::to_string(assignment_entry->offset) + ")";
  }
  if (bits & obj::kNodeAssignmentAsyncOnly) {
    n.error("node_id", "powerlink.cdc: " + named(obj::kNodeAssignment, id) + " marks node " +
                           std::to_string(id) +
                           " async-only (bit 8): ds1928d polls every CN it boots in the "
                           "isochronous phase and has no async-only CNs; remove the node or the "
                           "bit");
  }
  if (!n.has("mandatory") && assigned) node.mandatory = (bits & obj::kNodeAssignmentMandatory) != 0;
  note_source(sources, prefix + "mandatory", n.has("mandatory"), assignment_source);
  if (!n.has("prc") && assigned) node.prc = (bits & obj::kNodeAssignmentPrc) != 0;
  note_source(sources, prefix + "prc", n.has("prc"), assignment_source);
  if (!n.has("multiplexed") && !n.has("multiplex_slot")) {
    if (assigned) node.multiplexed = (bits & obj::kNodeAssignmentMultiplexed) != 0;
    if (const auto slot = value(obj::kMultiplCycleAssign); slot && node.multiplexed)
      node.multiplex_slot = static_cast<uint8_t>(std::min(*slot, 255u));
  }
  for (const MnCdcSetting& row : kSettings) {
    if (!row.per_node) continue;
    const bool given = n.has(row.key);
    std::string source;
    if (!given) {
      if (const auto v = mn_cdc_value(n, "node_id", row, mn, id, source)) {
        if (row.target == kPresTimeout) node.pres_timeout_us = static_cast<uint32_t>(*v);
        if (row.target == kLossOfPresThreshold)
          node.loss_of_pres_threshold = static_cast<uint32_t>(*v);
      }
    }
    note_source(sources, prefix + std::string(row.key), given, source);
  }
  if (!node.device_type) node.device_type = value(obj::kMnDeviceTypeIdList);
  if (!node.vendor_id) node.vendor_id = value(obj::kMnVendorIdList);
  if (!node.product_code) node.product_code = value(obj::kMnProductCodeList);
  if (!node.revision_no) node.revision_no = value(obj::kMnRevisionNoList);
  if (!node.serial_no) node.serial_no = value(obj::kMnSerialNoList);
  // CFM_ExpConfDateList/TimeList: checked when either is set (0 = not set), as the CDC's tool
  // and openPOWERLINK's MN read them; the YAML's pair wins as a whole.
  if (!node.expected_conf_date && !node.expected_conf_time) {
    node.expected_conf_date = value(obj::kExpConfDateList);
    node.expected_conf_time = value(obj::kExpConfTimeList);
  }
  if (!node.preq_size)
    if (const auto v = value(obj::kMnPReqPayloadLimitList))
      node.preq_size = static_cast<uint16_t>(std::min(*v, 1490u));
  if (!node.pres_size)
    if (const auto v = value(obj::kPResPayloadLimitList))
      node.pres_size = static_cast<uint16_t>(std::min(*v, 1490u));
}

void apply_mn_cdc_network(Section& s, const Section& thresholds, const Section& nmt,
                          PowerlinkBusConfig& p, std::span<const powerlink::CdcEntry> mn) {
  for (const MnCdcSetting& row : kSettings) {
    if (row.per_node || row.target == kCyclePeriod) continue;  // the period: see load_config()
    bool given = false;
    switch (row.target) {
      case kCycleTimeExceeded:
        given = thresholds.has("cycle_time_exceeded");
        break;
      case kWaitSocPreq:
        given = s.has("wait_soc_preq_us");
        break;
      case kAsyncSlotTimeout:
        given = s.has("async_slot_timeout_us") || s.has("async_timeout_us");
        break;
      case kPreOp1Timeout:
        given = nmt.has("pre_op1_timeout_ms");
        break;
      case kWaitNotActive:
        given = nmt.has("wait_not_active_ms");
        break;
      case kAsyncMtu:
        given = s.has("async_mtu");
        break;
      default:
        break;
    }
    std::string source;
    const auto v = given ? std::nullopt : mn_cdc_value(s, "cdc", row, mn, 0, source);
    if (v) {
      const auto u = static_cast<uint32_t>(*v);
      switch (row.target) {
        case kCycleTimeExceeded:
          p.thresholds.cycle_time_exceeded = u;
          break;
        case kWaitSocPreq:
          p.wait_soc_preq_us = u;
          break;
        case kAsyncSlotTimeout:
          p.async_timeout_us = u;
          break;
        case kPreOp1Timeout:
          p.nmt.pre_op1_timeout_ms = u;
          break;
        case kWaitNotActive:
          p.nmt.wait_not_active_ms = u;
          break;
        case kAsyncMtu:
          p.async_mtu = static_cast<uint16_t>(u);
          break;
        default:
          break;
      }
    }
    note_source(p.sources, std::string(row.key), given, source);
  }
}

void apply_mn_cdc_cycle(Section& powerlink, bool period_given, uint32_t& period_us,
                        std::span<const powerlink::CdcEntry> mn,
                        std::map<std::string, std::string>& sources) {
  for (const MnCdcSetting& row : kSettings) {
    if (row.target != kCyclePeriod) continue;
    std::string source;
    if (!period_given)
      if (const auto v = mn_cdc_value(powerlink, "cdc", row, mn, 0, source))
        period_us = static_cast<uint32_t>(*v);
    note_source(sources, std::string(row.key), period_given, source);
  }
}

}  // namespace ds1928::config_detail
