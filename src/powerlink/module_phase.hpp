// What a POWERLINK CN's state says of the X20DS1928 behind it (x20ds1928/module_state.hpp): the
// MN's boot step for the CN and the NMT state the CN last reported, mapped onto the phases the
// module's r-LED tells apart. The mapping is the project's reading (docs/operations.md "Module
// state"): the bus controller reports its own NMT state, not the module's LED. Pure.
#pragma once

#include "powerlink/frames.hpp"
#include "powerlink/managing_node.hpp"
#include "x20ds1928/module_state.hpp"

namespace ds1928::powerlink {

// `heard`: the CN answered its IdentRequest since the MN last (re)started identifying it
// (identified, or refused for its identity); while identifying, a CN not heard is Unknown
// whatever it reported before it went silent.
[[nodiscard]] NodePhase node_phase(CnBootState boot, NmtState reported, bool heard) noexcept;

}  // namespace ds1928::powerlink
