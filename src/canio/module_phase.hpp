// What a CAN-I/O node's NMT state says of the X20DS1928 behind it (x20ds1928/module_state.hpp):
// the state of its last boot-up or heartbeat message mapped onto the phases the module's r-LED
// tells apart. The mapping is the project's reading (docs/operations.md "Module state"): the bus
// controller reports its own NMT state, not the module's LED. Pure.
#pragma once

#include <cstdint>

#include "x20ds1928/module_state.hpp"

namespace ds1928::canio {

// `reported`: CanioNodeCounters::nmt_state (a canio::NmtState, 0xFF: none reported yet, or
// none since a heartbeat was missed). `silent`: the axis is configured but its samples stopped
// (CanioAxisState::Silent). `heartbeat_watched`: the node's heartbeat is consumed, so `reported`
// is current (a miss clears it). Without a heartbeat the last state heard may be long past (the
// boot-up, before the node was started): a silent node is then Unknown, whatever it said.
[[nodiscard]] NodePhase node_phase(uint8_t reported, bool silent, bool heartbeat_watched) noexcept;

}  // namespace ds1928::canio
