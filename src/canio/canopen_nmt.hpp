// CANopen network management and error control (CiA 301 §7.2.8, §7.2.7): the frames a CAN-I/O
// bus controller and its master exchange besides the process data and SDO. Pure: frames in,
// values out (and the reverse), no I/O.
//
//   NMT command      0x000, 2 bytes: command specifier, node (0 = all nodes)
//                    0x01 Start, 0x02 Stop, 0x80 Enter Pre-Operational, 0x81 Reset Node,
//                    0x82 Reset Communication
//   error control    0x700 + node, 1 byte: NMT state of the producer — 0x00 boot-up (the node
//                    has just (re)started: it is pre-operational and has lost its settings),
//                    0x04 stopped, 0x05 operational, 0x7F pre-operational (heartbeat); bit 7 is
//                    the node-guarding toggle and is ignored here
//   EMCY             0x080 + node, 8 bytes: error code (u16, little endian), error register
//                    (object 0x1001, u8), 5 manufacturer-specific bytes; an error code 0x0000
//                    means "error reset / no error"
//   heartbeat time   object 0x1017 sub 0, u16 ms (0 = no heartbeat produced)
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

#include "can/can_frame.hpp"

namespace ds1928::canio {

inline constexpr uint32_t kNmtCobId = 0x000;
inline constexpr uint32_t kErrorControlBase = 0x700;  // boot-up / heartbeat: 0x700 + node
inline constexpr uint32_t kEmcyBase = 0x080;          // EMCY: 0x080 + node (0x080 itself: SYNC)
inline constexpr uint16_t kHeartbeatProducerIndex = 0x1017;  // u16, ms

enum class NmtCommand : uint8_t {
  Start = 0x01,
  Stop = 0x02,
  EnterPreOperational = 0x80,
  ResetNode = 0x81,
  ResetCommunication = 0x82,
};
[[nodiscard]] std::string_view to_string(NmtCommand c) noexcept;

// What a node reports in its error-control frames.
enum class NmtState : uint8_t {
  BootUp = 0x00,
  Stopped = 0x04,
  Operational = 0x05,
  PreOperational = 0x7F,
};
[[nodiscard]] std::string_view to_string(NmtState s) noexcept;

// NMT command to `node` (0: every node). Node outside 0..127: nullopt.
[[nodiscard]] std::optional<CanFrame> build_nmt(NmtCommand command, uint8_t node) noexcept;
struct NmtMessage {
  NmtCommand command = NmtCommand::Start;
  uint8_t node = 0;  // 0: all nodes
};
// An NMT command frame (0x000, 2 bytes, known command): else nullopt.
[[nodiscard]] std::optional<NmtMessage> parse_nmt(const CanFrame& f) noexcept;
// True when `message` addresses `node`.
[[nodiscard]] constexpr bool addresses(const NmtMessage& m, uint8_t node) noexcept {
  return m.node == 0 || m.node == node;
}

// Boot-up or heartbeat of `node` (state BootUp for the boot-up message).
[[nodiscard]] std::optional<CanFrame> build_error_control(uint8_t node, NmtState state) noexcept;
struct ErrorControl {
  uint8_t node = 0;
  NmtState state = NmtState::BootUp;
};
// A frame on 0x701..0x77F with one data byte whose low 7 bits are a known state: else nullopt.
[[nodiscard]] std::optional<ErrorControl> parse_error_control(const CanFrame& f) noexcept;

struct Emcy {
  uint8_t node = 0;
  uint16_t error_code = 0;
  uint8_t error_register = 0;
  std::array<uint8_t, 5> vendor{};
  friend bool operator==(const Emcy&, const Emcy&) = default;
};
[[nodiscard]] std::optional<CanFrame> build_emcy(const Emcy& e) noexcept;
// A data frame on 0x081..0x0FF with 8 bytes (CiA 301 fixes the length): else nullopt.
[[nodiscard]] std::optional<Emcy> parse_emcy(const CanFrame& f) noexcept;

// The consumer's timeout for a producer time (ms): `timeout_ms` when set, else 1.5 × the producer
// time (ASSUMPTION, docs/canio.md: CiA 301 leaves the consumer's margin to the integrator).
[[nodiscard]] constexpr uint32_t heartbeat_consumer_ms(uint32_t producer_ms,
                                                       uint32_t timeout_ms) noexcept {
  return timeout_ms != 0 ? timeout_ms : producer_ms + (producer_ms + 1) / 2;
}

}  // namespace ds1928::canio
