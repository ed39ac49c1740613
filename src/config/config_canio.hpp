// The `canio` section of the configuration (internal to the configuration library).
#pragma once

#include <ostream>

#include "config/config.hpp"
#include "config/config_bus_kinds.hpp"
#include "config/config_reader.hpp"

namespace ds1928::config_detail {

// Parses the section into `c`; `axis_count` = entries of the top-level axes list.
void parse_canio(Section s, CanioBusConfig& c);

// Checks that need the whole document (axes, cycle) when the bus is canio: node numbers,
// MTUs, identifiers (range, collisions, predefined-set limits), timeouts, bus load.
// (bus canio's row of the bus kinds)
void check_canio(const BusDocument& d);

// The section as dump_config() prints it.
void dump_canio(std::ostream& o, const CanioBusConfig& c);

}  // namespace ds1928::config_detail
