// The module state and error class as the r- and e-LED would show them (datasheet §4
// "Status-LEDs"): the derivation from the node's phase and the data's arrival, the e-LED from the
// error table's column, and each bus' table of node states (POWERLINK CN, CAN-I/O node).
#include "x20ds1928/module_state.hpp"

#include <catch2/catch.hpp>

#include "canio/canopen_nmt.hpp"
#include "canio/module_phase.hpp"
#include "powerlink/module_phase.hpp"

using namespace ds1928;

TEST_CASE("Module state: data arriving is RUN, else the node's phase", "[module_state]") {
  for (const NodePhase p : {NodePhase::Unknown, NodePhase::Reset, NodePhase::Boot, NodePhase::PreOp,
                            NodePhase::Operational})
    CHECK(derive_module_state({p, true}) == ModuleState::Run);
  CHECK(derive_module_state({NodePhase::Unknown, false}) == ModuleState::Off);
  CHECK(derive_module_state({NodePhase::Reset, false}) == ModuleState::Reset);
  CHECK(derive_module_state({NodePhase::Boot, false}) == ModuleState::Boot);
  CHECK(derive_module_state({NodePhase::PreOp, false}) == ModuleState::PreOp);
  // The node runs, this module's data does not arrive (not configured, not delivering).
  CHECK(derive_module_state({NodePhase::Operational, false}) == ModuleState::PreOp);
  CHECK(r_led(ModuleState::Off) == LedPattern::Off);
  CHECK(r_led(ModuleState::Reset) == LedPattern::SingleFlash);
  CHECK(r_led(ModuleState::Boot) == LedPattern::DoubleFlash);
  CHECK(r_led(ModuleState::PreOp) == LedPattern::Blinking);
  CHECK(r_led(ModuleState::Run) == LedPattern::On);
  CHECK(to_string(ModuleState::PreOp) == "preop");
}

TEST_CASE("Module state: the data counts as arriving within the window only", "[module_state]") {
  constexpr int64_t t = 5'000'000'000;
  CHECK_FALSE(data_arrives(0, t, 1000));  // never
  CHECK(data_arrives(t, t, 1000));
  CHECK(data_arrives(t - kArrivalWindowNs, t, 1000));
  CHECK_FALSE(data_arrives(t - kArrivalWindowNs - 1, t, 1000));
  // A long period: three cycles, not 100 ms.
  CHECK(data_arrives(t - 3 * 50'000'000, t, 50'000));
  CHECK_FALSE(data_arrives(t - 3 * 50'000'000 - 1, t, 50'000));
}

TEST_CASE("Module state: the e-LED's class from the set ErrorInfo bits", "[module_state]") {
  const auto cls = [](uint8_t info, uint16_t error = 0, uint16_t warning = 0) {
    return module_error_class(ModuleState::Run, ErrorWords{info, error, warning});
  };
  CHECK(cls(0) == ModuleErrorClass::None);
  CHECK(cls(0x01) == ModuleErrorClass::Supply);  // EncoderSupplyError: on
  CHECK(cls(0x04) == ModuleErrorClass::Io);      // VssCheckError: single flash (wire break)
  CHECK(cls(0x08) == ModuleErrorClass::Io);      // PositionError (sin/cos)
  CHECK(cls(0x80) == ModuleErrorClass::Io);      // EnDatRefWarning (reference)
  CHECK(cls(0x10) == ModuleErrorClass::System);  // EnDatComError: double flash
  CHECK(cls(0x20) == ModuleErrorClass::System);  // EnDatPosError
  CHECK(cls(0x40) == ModuleErrorClass::System);  // EnDatParSetError
  CHECK(cls(0x14) == ModuleErrorClass::IoAndSystem);
  CHECK(cls(0x15) == ModuleErrorClass::Supply);  // the supply outranks: the LED is on
  CHECK(cls(0x02) == ModuleErrorClass::None);    // reserved
  // The encoder's own words light nothing of their own.
  CHECK(cls(0, 0xFFFF, 0xFFFF) == ModuleErrorClass::None);
  CHECK(module_error_class(ModuleState::Reset, {}) == ModuleErrorClass::Reset);
  CHECK(e_led(ModuleErrorClass::None) == LedPattern::Off);
  CHECK(e_led(ModuleErrorClass::Reset) == LedPattern::On);
  CHECK(e_led(ModuleErrorClass::Supply) == LedPattern::On);
  CHECK(e_led(ModuleErrorClass::Io) == LedPattern::SingleFlash);
  CHECK(e_led(ModuleErrorClass::System) == LedPattern::DoubleFlash);
  CHECK(e_led(ModuleErrorClass::IoAndSystem) == LedPattern::TripleFlash);
  // Every ErrorInfo bit of the table has its e-LED group; no encoder word bit has one.
  for (const ErrorBit& b : error_bits())
    CHECK((b.reg == ErrorRegister::ErrorInfo) == (b.led != ErrorLed::None));
}

TEST_CASE("Module state: a POWERLINK CN's boot step and NMT state", "[module_state]") {
  using powerlink::CnBootState;
  using powerlink::NmtState;
  // Not heard since the MN began to identify it: whatever it said before it went silent.
  CHECK(powerlink::node_phase(CnBootState::kIdentify, NmtState::kOperational, false) ==
        NodePhase::Unknown);
  // Refused for its identity: heard, stuck in its boot.
  CHECK(powerlink::node_phase(CnBootState::kIdentify, NmtState::kPreOperational1, true) ==
        NodePhase::Boot);
  CHECK(powerlink::node_phase(CnBootState::kReset, NmtState::kOperational, true) ==
        NodePhase::Reset);
  CHECK(powerlink::node_phase(CnBootState::kResetConfiguration, NmtState::kPreOperational2, true) ==
        NodePhase::Reset);
  CHECK(powerlink::node_phase(CnBootState::kWaitPreOp2, NmtState::kNotActive, true) ==
        NodePhase::Boot);
  CHECK(powerlink::node_phase(CnBootState::kConfigure, NmtState::kPreOperational2, true) ==
        NodePhase::PreOp);
  CHECK(powerlink::node_phase(CnBootState::kWaitOperational, NmtState::kReadyToOperate, true) ==
        NodePhase::PreOp);
  CHECK(powerlink::node_phase(CnBootState::kOperational, NmtState::kStopped, true) ==
        NodePhase::PreOp);
  CHECK(powerlink::node_phase(CnBootState::kOperational, NmtState::kOperational, true) ==
        NodePhase::Operational);
  CHECK(powerlink::node_phase(CnBootState::kOperational, NmtState::kResetCommunication, true) ==
        NodePhase::Reset);
  CHECK(powerlink::node_phase(CnBootState::kOperational, NmtState::kOff, true) ==
        NodePhase::Unknown);
}

TEST_CASE("Module state: a CAN-I/O node's reported NMT state", "[module_state]") {
  using canio::NmtState;
  const auto phase = [](NmtState s, bool silent = false, bool heartbeat = false) {
    return canio::node_phase(static_cast<uint8_t>(s), silent, heartbeat);
  };
  CHECK(canio::node_phase(0xFF, false, false) == NodePhase::Unknown);  // nothing reported yet
  CHECK(canio::node_phase(0xFF, false, true) == NodePhase::Unknown);   // a heartbeat missed
  CHECK(phase(NmtState::BootUp) == NodePhase::Boot);
  CHECK(phase(NmtState::PreOperational) == NodePhase::PreOp);
  CHECK(phase(NmtState::Stopped) == NodePhase::PreOp);
  CHECK(phase(NmtState::Operational) == NodePhase::Operational);
  CHECK(canio::node_phase(0x42, false, false) == NodePhase::Unknown);  // no state of CiA 301
  // Its samples stopped: without a heartbeat the boot-up heard long ago says nothing now.
  CHECK(phase(NmtState::BootUp, true, false) == NodePhase::Unknown);
  CHECK(phase(NmtState::Operational, true, false) == NodePhase::Unknown);
  // With a heartbeat the state is current: a stopped node is silent and says so.
  CHECK(phase(NmtState::Stopped, true, true) == NodePhase::PreOp);
}
