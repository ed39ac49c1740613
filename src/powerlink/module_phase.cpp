#include "powerlink/module_phase.hpp"

#include <array>

namespace ds1928::powerlink {
namespace {

struct PhaseRow {
  NmtState state;
  NodePhase phase;
};

// EPSG DS 301 §7.1 NMT states of a CN: the reset states before it answers, NOT_ACTIVE and
// PRE_OPERATIONAL_1 while the MN identifies and configures it (its boot), PRE_OPERATIONAL_2,
// READY_TO_OPERATE and STOPPED without valid cyclic data, OPERATIONAL.
constexpr std::array<PhaseRow, 12> kPhases{{
    {NmtState::kOff, NodePhase::Unknown},
    {NmtState::kInitialising, NodePhase::Reset},
    {NmtState::kResetApplication, NodePhase::Reset},
    {NmtState::kResetCommunication, NodePhase::Reset},
    {NmtState::kResetConfiguration, NodePhase::Reset},
    {NmtState::kNotActive, NodePhase::Boot},
    {NmtState::kPreOperational1, NodePhase::Boot},
    {NmtState::kBasicEthernet, NodePhase::Boot},
    {NmtState::kPreOperational2, NodePhase::PreOp},
    {NmtState::kReadyToOperate, NodePhase::PreOp},
    {NmtState::kStopped, NodePhase::PreOp},
    {NmtState::kOperational, NodePhase::Operational},
}};

}  // namespace

NodePhase node_phase(CnBootState boot, NmtState reported, bool heard) noexcept {
  // The MN reset the CN (NMTResetNode, NMTResetConfiguration) and waits for it to come back.
  if (boot == CnBootState::kReset || boot == CnBootState::kResetConfiguration)
    return NodePhase::Reset;
  if (boot == CnBootState::kIdentify && !heard) return NodePhase::Unknown;
  for (const PhaseRow& r : kPhases)
    if (r.state == reported) return r.phase;
  return NodePhase::Unknown;
}

}  // namespace ds1928::powerlink
