#include "canio/canopen_nmt.hpp"

namespace ds1928::canio {
namespace {

[[nodiscard]] constexpr bool valid_node(uint8_t node) noexcept {
  return node >= 1 && node <= 127;
}

[[nodiscard]] bool known_command(uint8_t cs) noexcept {
  switch (static_cast<NmtCommand>(cs)) {
    case NmtCommand::Start:
    case NmtCommand::Stop:
    case NmtCommand::EnterPreOperational:
    case NmtCommand::ResetNode:
    case NmtCommand::ResetCommunication:
      return true;
  }
  return false;
}

[[nodiscard]] bool known_state(uint8_t s) noexcept {
  switch (static_cast<NmtState>(s)) {
    case NmtState::BootUp:
    case NmtState::Stopped:
    case NmtState::Operational:
    case NmtState::PreOperational:
      return true;
  }
  return false;
}

}  // namespace

std::string_view to_string(NmtCommand c) noexcept {
  switch (c) {
    case NmtCommand::Start:
      return "start";
    case NmtCommand::Stop:
      return "stop";
    case NmtCommand::EnterPreOperational:
      return "enter-pre-operational";
    case NmtCommand::ResetNode:
      return "reset-node";
    case NmtCommand::ResetCommunication:
      return "reset-communication";
  }
  return "?";
}

std::string_view to_string(NmtState s) noexcept {
  switch (s) {
    case NmtState::BootUp:
      return "boot-up";
    case NmtState::Stopped:
      return "stopped";
    case NmtState::Operational:
      return "operational";
    case NmtState::PreOperational:
      return "pre-operational";
  }
  return "?";
}

std::optional<CanFrame> build_nmt(NmtCommand command, uint8_t node) noexcept {
  if (node > 127) return std::nullopt;
  const std::array<uint8_t, 2> bytes{static_cast<uint8_t>(command), node};
  return make_standard_frame(kNmtCobId, bytes);
}

std::optional<NmtMessage> parse_nmt(const CanFrame& f) noexcept {
  if (f.error || f.extended || f.rtr || f.id != kNmtCobId || f.dlc != 2) return std::nullopt;
  if (!known_command(f.data[0]) || f.data[1] > 127) return std::nullopt;
  return NmtMessage{static_cast<NmtCommand>(f.data[0]), f.data[1]};
}

std::optional<CanFrame> build_error_control(uint8_t node, NmtState state) noexcept {
  if (!valid_node(node)) return std::nullopt;
  const std::array<uint8_t, 1> bytes{static_cast<uint8_t>(state)};
  return make_standard_frame(kErrorControlBase + node, bytes);
}

std::optional<ErrorControl> parse_error_control(const CanFrame& f) noexcept {
  if (f.error || f.extended || f.rtr || f.dlc != 1) return std::nullopt;
  if (f.id <= kErrorControlBase || f.id > kErrorControlBase + 127) return std::nullopt;
  const auto state = static_cast<uint8_t>(f.data[0] & 0x7F);  // bit 7: node-guarding toggle
  if (!known_state(state)) return std::nullopt;
  return ErrorControl{static_cast<uint8_t>(f.id - kErrorControlBase), static_cast<NmtState>(state)};
}

std::optional<CanFrame> build_emcy(const Emcy& e) noexcept {
  if (!valid_node(e.node)) return std::nullopt;
  const std::array<uint8_t, 8> bytes{static_cast<uint8_t>(e.error_code & 0xFF),
                                     static_cast<uint8_t>(e.error_code >> 8),
                                     e.error_register,
                                     e.vendor[0],
                                     e.vendor[1],
                                     e.vendor[2],
                                     e.vendor[3],
                                     e.vendor[4]};
  return make_standard_frame(kEmcyBase + e.node, bytes);
}

std::optional<Emcy> parse_emcy(const CanFrame& f) noexcept {
  if (f.error || f.extended || f.rtr || f.dlc != 8) return std::nullopt;
  if (f.id <= kEmcyBase || f.id > kEmcyBase + 127) return std::nullopt;
  Emcy e;
  e.node = static_cast<uint8_t>(f.id - kEmcyBase);
  e.error_code = static_cast<uint16_t>(f.data[0] | (f.data[1] << 8));
  e.error_register = f.data[2];
  for (std::size_t k = 0; k < e.vendor.size(); ++k) e.vendor[k] = f.data[3 + k];
  return e;
}

}  // namespace ds1928::canio
