// The `powerlink` section of the configuration (docs/configuration.md, docs/powerlink.md):
// parsing, the checks that need the axes and the cycle, and its part of the effective dump.
// Internal to src/config.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <ostream>
#include <utility>
#include <vector>

#include "config/config_bus_kinds.hpp"
#include "config/config_reader.hpp"
#include "powerlink/concise_dcf.hpp"

namespace ds1928::config_detail {

// Where the parts of the section were written, for messages of later cross-field checks.
struct PowerlinkSites {
  bool interface_refused = false;    // given but invalid: reported already, not "missing"
  std::map<uint8_t, Loc> nodes;      // node id → where it is listed
  std::vector<Loc> pres_timeout_at;  // per nodes[] entry
  std::vector<std::optional<Loc>> pres_latency_at;  // per nodes[] entry, where given
  Loc async_timeout_at;                // where the budget check points when the cycle is too long
  std::optional<Loc> pres_mn_size_at;  // where pres_mn_size was given, if it was
  // Multiplexed nodes: where multiplex_slot (else multiplexed) was given, index in nodes.
  std::vector<std::pair<Loc, std::size_t>> multiplexed;
  // The MN's concise DCF (powerlink.cdc), decoded: its NMT_CycleLen sets cycle.period_us.
  std::vector<powerlink::CdcEntry> mn_cdc;
};

// `base_dir`: where relative file names (cdc) are resolved.
void parse_powerlink(Section s, PowerlinkBusConfig& p, PowerlinkSites& sites,
                     const std::filesystem::path& base_dir);

// Checks of the section against the axes and the cycle (bus powerlink's row of the bus kinds):
// the interface is given, every axis' node is listed, process images, timeouts, cycle budget.
void check_powerlink(const BusDocument& d);

void dump_powerlink(std::ostream& o, const PowerlinkBusConfig& p);

// The bytes a chained (prc) node's outputs take in the PResMN: the end of its packed blocks
// (or offsets), or of its written RPDO mapping.
[[nodiscard]] std::size_t output_image_size(const DaemonConfig& c, const PowerlinkNodeConfig& n);

// The nominal cycle must fit the period; the PResMN must carry the chained nodes' outputs
// (config_powerlink_budget.cpp).
void check_cycle_budget(Diagnostics& diag, const DaemonConfig& c, const PowerlinkSites& sites);

// "  # <where the value came from>" for a key the MN's CDC can set (p.sources), else empty.
[[nodiscard]] std::string source_comment(const PowerlinkBusConfig& p, const std::string& key);

}  // namespace ds1928::config_detail
