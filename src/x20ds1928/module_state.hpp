// The module's two status LEDs (datasheet §4 "Status-LEDs") as the daemon reconstructs them from
// what the bus shows: the green r-LED as the module state (off / reset / boot / preop / run) and
// the red e-LED as the error class it flashes. Neither bus controller reads the LEDs out; how each
// bus' node states map to them is the project's reading (docs/operations.md "Module state"). Pure.
#pragma once

#include <cstdint>
#include <string_view>

#include "x20ds1928/error_bits.hpp"

namespace ds1928 {

// The r-LED: off (not supplied), single flash RESET, double flash BOOT, blinking PREOPERATIONAL,
// on RUN.
enum class ModuleState : uint8_t { Off = 0, Reset = 1, Boot = 2, PreOp = 3, Run = 4 };

// What a bus shows of the node (POWERLINK CN, CAN-I/O node) that holds the module, reduced to the
// phases the r-LED tells apart. Each bus maps its own node states onto these in one table
// (powerlink/module_phase.cpp, canio/module_phase.cpp).
enum class NodePhase : uint8_t {
  Unknown = 0,      // not heard: no answer, no boot-up, no heartbeat
  Reset = 1,        // in a reset or initialisation state
  Boot = 2,         // booting: heard, being identified and configured by the master
  PreOp = 3,        // pre-operational, ready to operate or stopped: no cyclic data
  Operational = 4,  // operational
};

struct ModuleView {
  NodePhase node = NodePhase::Unknown;
  // The module's own inputs arrived new within the arrival window (kArrivalWindowNs): data in
  // the cyclic image proves the module runs whatever the node's last reported state.
  bool data_arrives = false;
};

// How long after the last new input the module still counts as delivering: a lost frame or two
// does not make it leave RUN.
inline constexpr int64_t kArrivalWindowNs = 100'000'000;
// At least this many cycles, for long cycle periods.
inline constexpr uint64_t kArrivalWindowCycles = 3;

// Whether the module's data arrives: its last new input (`last_input_ns`, 0: never) lies within
// the arrival window before `now_ns` (both on the cycle's clock).
[[nodiscard]] constexpr bool data_arrives(int64_t last_input_ns, int64_t now_ns,
                                          uint32_t period_us) noexcept {
  if (last_input_ns == 0) return false;
  const auto cycles = static_cast<int64_t>(kArrivalWindowCycles * period_us * 1000);
  const int64_t window = cycles > kArrivalWindowNs ? cycles : kArrivalWindowNs;
  return now_ns - last_input_ns <= window;
}

[[nodiscard]] constexpr ModuleState derive_module_state(const ModuleView& v) noexcept {
  if (v.data_arrives) return ModuleState::Run;
  switch (v.node) {
    case NodePhase::Unknown:
      return ModuleState::Off;
    case NodePhase::Reset:
      return ModuleState::Reset;
    case NodePhase::Boot:
      return ModuleState::Boot;
    case NodePhase::PreOp:
    case NodePhase::Operational:  // the node runs, this module's data does not arrive
      return ModuleState::PreOp;
  }
  return ModuleState::Off;
}

// The class of error the e-LED shows, and how: none (off), reset (on), supply (on), io (single
// flash), system (double flash), io_and_system (triple flash).
enum class ModuleErrorClass : uint8_t { None, Reset, Supply, Io, System, IoAndSystem };
enum class LedPattern : uint8_t { Off, On, SingleFlash, DoubleFlash, TripleFlash, Blinking };

// From the set ErrorInfo bits (the error table's e-LED column) and the module state: a module in
// reset lights the e-LED; the supply error outranks the flashes (the LED is on). Only ErrorInfo
// counts: the encoder's own words light nothing of their own.
[[nodiscard]] ModuleErrorClass module_error_class(ModuleState state,
                                                  const ErrorWords& words) noexcept;

[[nodiscard]] LedPattern r_led(ModuleState s) noexcept;
[[nodiscard]] LedPattern e_led(ModuleErrorClass c) noexcept;
[[nodiscard]] std::string_view to_string(ModuleState s) noexcept;
[[nodiscard]] std::string_view to_string(NodePhase p) noexcept;
[[nodiscard]] std::string_view to_string(ModuleErrorClass c) noexcept;
[[nodiscard]] std::string_view to_string(LedPattern p) noexcept;

}  // namespace ds1928
