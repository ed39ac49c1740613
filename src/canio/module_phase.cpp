#include "canio/module_phase.hpp"

#include <array>

#include "canio/canopen_nmt.hpp"

namespace ds1928::canio {
namespace {

struct PhaseRow {
  NmtState state;
  NodePhase phase;
};

// CiA 301 §7.3.2: the boot-up message ends the node's initialisation (it then waits
// pre-operational to be configured and started: its boot as the master sees it); PDOs flow only
// in OPERATIONAL.
constexpr std::array<PhaseRow, 4> kPhases{{
    {NmtState::BootUp, NodePhase::Boot},
    {NmtState::PreOperational, NodePhase::PreOp},
    {NmtState::Stopped, NodePhase::PreOp},
    {NmtState::Operational, NodePhase::Operational},
}};

}  // namespace

NodePhase node_phase(uint8_t reported, bool silent, bool heartbeat_watched) noexcept {
  if (silent && !heartbeat_watched) return NodePhase::Unknown;
  for (const PhaseRow& r : kPhases)
    if (static_cast<uint8_t>(r.state) == reported) return r.phase;
  return NodePhase::Unknown;
}

}  // namespace ds1928::canio
