// The `powerlink` section of the configuration (docs/configuration.md, docs/powerlink.md):
// parsing, the checks that need the axes and the cycle, and its part of the effective dump.
// Internal to src/config.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <ostream>
#include <vector>

#include "config/config_reader.hpp"

namespace ds1928::config_detail {

// Where the parts of the section were written, for messages of later cross-field checks.
struct PowerlinkSites {
  bool present = false;
  std::map<uint8_t, Loc> nodes;      // node id → where it is listed
  std::vector<Loc> pres_timeout_at;  // per nodes[] entry
};

// `base_dir`: where relative file names (cdc) are resolved.
void parse_powerlink(Section s, PowerlinkBusConfig& p, PowerlinkSites& sites,
                     const std::filesystem::path& base_dir);

// Checks of the section against the axes and the cycle (only called on bus powerlink).
void check_powerlink(Diagnostics& diag, const DaemonConfig& c, const std::vector<AxisSite>& axes,
                     const PowerlinkSites& sites);

void dump_powerlink(std::ostream& o, const PowerlinkBusConfig& p);

}  // namespace ds1928::config_detail
