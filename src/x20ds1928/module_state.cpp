#include "x20ds1928/module_state.hpp"

namespace ds1928 {

ModuleErrorClass module_error_class(ModuleState state, const ErrorWords& words) noexcept {
  if (state == ModuleState::Reset) return ModuleErrorClass::Reset;
  bool io = false;
  bool system = false;
  for (const ErrorBit& b : error_bits()) {
    if ((words[b.reg] & (1u << b.bit)) == 0) continue;
    switch (b.led) {
      case ErrorLed::Supply:
        return ModuleErrorClass::Supply;
      case ErrorLed::Io:
        io = true;
        break;
      case ErrorLed::System:
        system = true;
        break;
      case ErrorLed::None:
        break;
    }
  }
  if (io && system) return ModuleErrorClass::IoAndSystem;
  if (io) return ModuleErrorClass::Io;
  if (system) return ModuleErrorClass::System;
  return ModuleErrorClass::None;
}

LedPattern r_led(ModuleState s) noexcept {
  switch (s) {
    case ModuleState::Off:
      return LedPattern::Off;
    case ModuleState::Reset:
      return LedPattern::SingleFlash;
    case ModuleState::Boot:
      return LedPattern::DoubleFlash;
    case ModuleState::PreOp:
      return LedPattern::Blinking;
    case ModuleState::Run:
      return LedPattern::On;
  }
  return LedPattern::Off;
}

LedPattern e_led(ModuleErrorClass c) noexcept {
  switch (c) {
    case ModuleErrorClass::None:
      return LedPattern::Off;
    case ModuleErrorClass::Reset:
    case ModuleErrorClass::Supply:
      return LedPattern::On;
    case ModuleErrorClass::Io:
      return LedPattern::SingleFlash;
    case ModuleErrorClass::System:
      return LedPattern::DoubleFlash;
    case ModuleErrorClass::IoAndSystem:
      return LedPattern::TripleFlash;
  }
  return LedPattern::Off;
}

std::string_view to_string(ModuleState s) noexcept {
  switch (s) {
    case ModuleState::Off:
      return "off";
    case ModuleState::Reset:
      return "reset";
    case ModuleState::Boot:
      return "boot";
    case ModuleState::PreOp:
      return "preop";
    case ModuleState::Run:
      return "run";
  }
  return "?";
}

std::string_view to_string(NodePhase p) noexcept {
  switch (p) {
    case NodePhase::Unknown:
      return "unknown";
    case NodePhase::Reset:
      return "reset";
    case NodePhase::Boot:
      return "boot";
    case NodePhase::PreOp:
      return "preop";
    case NodePhase::Operational:
      return "operational";
  }
  return "?";
}

std::string_view to_string(ModuleErrorClass c) noexcept {
  switch (c) {
    case ModuleErrorClass::None:
      return "none";
    case ModuleErrorClass::Reset:
      return "reset";
    case ModuleErrorClass::Supply:
      return "supply";
    case ModuleErrorClass::Io:
      return "io";
    case ModuleErrorClass::System:
      return "system";
    case ModuleErrorClass::IoAndSystem:
      return "io_and_system";
  }
  return "?";
}

std::string_view to_string(LedPattern p) noexcept {
  switch (p) {
    case LedPattern::Off:
      return "off";
    case LedPattern::On:
      return "on";
    case LedPattern::SingleFlash:
      return "single_flash";
    case LedPattern::DoubleFlash:
      return "double_flash";
    case LedPattern::TripleFlash:
      return "triple_flash";
    case LedPattern::Blinking:
      return "blinking";
  }
  return "?";
}

}  // namespace ds1928
