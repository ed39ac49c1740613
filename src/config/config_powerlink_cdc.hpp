// The MN's concise DCF (openCONFIGURATOR's mnobd.cdc) as configuration: the MN objects it
// carries set ds1928d's keys wherever the YAML leaves them unset (docs/configuration.md §The
// MN's concise DCF). Internal to src/config.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "config/config.hpp"
#include "config/config_reader.hpp"
#include "powerlink/concise_dcf.hpp"

namespace ds1928::config_detail {

// What a setting of the table sets.
enum class MnCdcTarget : uint8_t {
  kCyclePeriod,          // cycle.period_us
  kCycleTimeExceeded,    // powerlink.thresholds.cycle_time_exceeded
  kWaitSocPreq,          // powerlink.wait_soc_preq_us
  kAsyncSlotTimeout,     // powerlink.async_slot_timeout_us
  kPreOp1Timeout,        // powerlink.nmt.pre_op1_timeout_ms
  kWaitNotActive,        // powerlink.nmt.wait_not_active_ms
  kAsyncMtu,             // powerlink.async_mtu
  kPresTimeout,          // powerlink.nodes[].pres_timeout_us
  kLossOfPresThreshold,  // powerlink.nodes[].loss_of_pres_threshold
};

// One MN object of the CDC and the key it stands for. Values convert from the object's unit to
// the key's by `divisor`, rounded up (a timeout is never shortened); the key's range is what
// ds1928d accepts for it, the object's minimum DS 301's (below it the CDC is wrong, not us).
struct MnCdcSetting {
  uint16_t index;
  uint8_t subindex;  // per node: the node id is the sub-index
  bool per_node;
  MnCdcTarget target;
  std::string_view key;  // per node: below powerlink.nodes[i]
  uint32_t divisor;
  uint32_t object_min;
  uint64_t key_min, key_max;
  std::string_view unit;  // the object's, for messages
};

[[nodiscard]] std::span<const MnCdcSetting> mn_cdc_settings() noexcept;

// The value `setting` takes from the CDC `mn` (node id for a per-node row), converted to its
// key's unit; nullopt when the CDC lacks the object. Out of range: an error at `s`'s `key`
// naming the object, its value and byte offset in the CDC, the range, and nullopt. `source`
// gets the text --print-config shows for it.
[[nodiscard]] std::optional<uint64_t> mn_cdc_value(Section& s, std::string_view key,
                                                   const MnCdcSetting& setting,
                                                   std::span<const powerlink::CdcEntry> mn,
                                                   uint8_t node, std::string& source);

// The node's objects, identity, role bits (NodeAssignment: mandatory, multiplexed, PRC; an
// async-only node is refused) and its per-node MN objects (PRes timeout, loss-of-PRes threshold)
// from the MN's concise DCF; what the YAML gives wins. `sources` gets "powerlink.nodes[i].<key>"
// → cdc / yaml / default for the keys the CDC can set.
void apply_mn_cdc(Section& n, PowerlinkNodeConfig& node, std::size_t i,
                  std::span<const powerlink::CdcEntry> mn, bool node_has_own_cdc,
                  std::map<std::string, std::string>& sources);

// The network-wide MN objects (thresholds, NMT boot time, WaitSoCPReq, AsyncSlotTimeout,
// AsyncMTU) on the
// powerlink section `s` and its `thresholds` / `nmt` sections, where those leave them unset.
void apply_mn_cdc_network(Section& s, const Section& thresholds, const Section& nmt,
                          PowerlinkBusConfig& p, std::span<const powerlink::CdcEntry> mn);

// NMT_CycleLen (0x1006) of the MN's CDC as cycle.period_us unless `period_given`; errors at
// `powerlink`'s cdc key.
void apply_mn_cdc_cycle(Section& powerlink, bool period_given, uint32_t& period_us,
                        std::span<const powerlink::CdcEntry> mn,
                        std::map<std::string, std::string>& sources);

}  // namespace ds1928::config_detail
