// SocketCAN error frames (linux/can/error.h) decoded into a typed event, and built back from one
// (the virtual bus injects error frames exactly as a kernel driver would send them).
//
// An error frame has CAN_ERR_FLAG set in can_id, the error classes as bits of the rest of can_id
// and dlc 8: data[0] arbitration-lost bit, data[1] controller status, data[2..3] protocol
// violation type and location, data[4] transceiver status, data[5] controller specific,
// data[6..7] TX/RX error counters (flagged by CAN_ERR_CNT on kernels from 6.1 on; older drivers
// fill them without the flag).
#pragma once

#include <cstdint>
#include <optional>

#include "can/can_frame.hpp"
#include "can/can_state.hpp"
#include "can/errors.hpp"

namespace ds1928::canio {

// Error classes (bits of CanFrame::id of an error frame), values of linux/can/error.h.
namespace err_class {
inline constexpr uint32_t kTxTimeout = 0x001;
inline constexpr uint32_t kLostArbitration = 0x002;
inline constexpr uint32_t kController = 0x004;
inline constexpr uint32_t kProtocol = 0x008;
inline constexpr uint32_t kTransceiver = 0x010;
inline constexpr uint32_t kNoAck = 0x020;
inline constexpr uint32_t kBusOff = 0x040;
inline constexpr uint32_t kBusError = 0x080;
inline constexpr uint32_t kRestarted = 0x100;
inline constexpr uint32_t kCounters = 0x200;
inline constexpr uint32_t kAll = 0x3FF;
}  // namespace err_class

// data[1]: controller problems.
namespace err_ctrl {
inline constexpr uint8_t kRxOverflow = 0x01;
inline constexpr uint8_t kTxOverflow = 0x02;
inline constexpr uint8_t kRxWarning = 0x04;
inline constexpr uint8_t kTxWarning = 0x08;
inline constexpr uint8_t kRxPassive = 0x10;
inline constexpr uint8_t kTxPassive = 0x20;
inline constexpr uint8_t kActive = 0x40;  // back to error-active
}  // namespace err_ctrl

// data[2]: protocol violation type.
namespace err_prot {
inline constexpr uint8_t kBit = 0x01;
inline constexpr uint8_t kForm = 0x02;
inline constexpr uint8_t kStuff = 0x04;
inline constexpr uint8_t kBit0 = 0x08;  // could not send a dominant bit
inline constexpr uint8_t kBit1 = 0x10;  // could not send a recessive bit
inline constexpr uint8_t kOverload = 0x20;
inline constexpr uint8_t kActive = 0x40;  // active error announcement
inline constexpr uint8_t kTx = 0x80;      // the error occurred on transmission
}  // namespace err_prot

// The error classes the ports subscribe to (CAN_RAW_ERR_FILTER): everything that changes what the
// master must do. Bus errors and lost arbitration are left out: they may flood (one per bit error)
// and the counters and state changes already carry their consequence. Protocol violations are
// left out too: the kernel's CAN drivers report every bus error as CAN_ERR_PROT |
// CAN_ERR_BUSERROR, and the kernel delivers an error frame when any of its class bits is
// subscribed — subscribing to protocol violations would let every bus error wake the cycle.
inline constexpr uint32_t kDefaultErrorMask = err_class::kTxTimeout | err_class::kController |
                                              err_class::kNoAck | err_class::kBusOff |
                                              err_class::kRestarted | err_class::kTransceiver;

struct CanErrorEvent {
  uint32_t classes = 0;  // err_class bits present

  bool tx_timeout = false;
  bool lost_arbitration = false;
  uint8_t arbitration_bit = 0;  // data[0], 0 = unspecified
  bool controller = false;
  uint8_t controller_status = 0;  // data[1], err_ctrl bits
  bool protocol = false;
  uint8_t protocol_type = 0;      // data[2], err_prot bits
  uint8_t protocol_location = 0;  // data[3], CAN_ERR_PROT_LOC_*
  bool transceiver = false;
  uint8_t transceiver_status = 0;  // data[4]
  bool no_ack = false;
  bool bus_off = false;
  bool bus_error = false;
  bool restarted = false;
  uint8_t controller_specific = 0;  // data[5]
  // data[6..7]; counters_flagged when the driver set CAN_ERR_CNT (counters valid for sure).
  bool counters_flagged = false;
  uint8_t tx_error_count = 0;
  uint8_t rx_error_count = 0;

  // The confinement state this event announces, if it announces one: bus-off, restarted
  // (→ error-active), controller passive / warning / active bits. Otherwise nullopt (a protocol
  // violation alone does not change the state).
  [[nodiscard]] std::optional<CanState> state_change() const noexcept;

  friend bool operator==(const CanErrorEvent&, const CanErrorEvent&) = default;
};

// Decodes an error frame. Errors: CanError::kNotAnErrorFrame (error flag not set),
// CanError::kErrorFrameLength (dlc is not 8), CanError::kUnknownErrorClass (bits above
// CAN_ERR_CNT set: a newer kernel's class this code does not know — the rest is still decodable
// by masking, but the caller is told).
[[nodiscard]] Result<CanErrorEvent> decode_error_frame(const CanFrame& frame) noexcept;

// The error frame a kernel driver would deliver for `event` (classes recomputed from the flags).
[[nodiscard]] CanFrame encode_error_frame(const CanErrorEvent& event) noexcept;

// A short human text for logs and status, e.g. "bus-off", "controller: rx-passive tx-warning",
// "protocol: stuff error at data section (tx)". Written into `out` (truncated), returns length.
std::size_t describe(const CanErrorEvent& event, char* out, std::size_t size) noexcept;

}  // namespace ds1928::canio
