// The CAN port: what a CAN-I/O bus driver needs from a CAN interface. Two implementations:
// SocketCanPort (socketcan_port.hpp, the real kernel CAN stack) and VirtualCanPort
// (virtual_bus.hpp, a test transport).
//
// Threads: send() and receive() belong to ONE thread, the cycle thread. They never allocate, never
// lock, never throw, and make at most the bus I/O syscalls (SocketCAN: one sendmsg / one
// recvmmsg, plus ppoll while waiting). state() and counters() may be read from any thread.
// Configuration calls (set_filters, set_error_mask, query_interface) belong to the normal thread
// and are made before the cycle starts or while it is paused.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <system_error>

#include "can/can_frame.hpp"
#include "can/can_state.hpp"
#include "can/errors.hpp"

namespace ds1928::canio {

enum class SendStatus : uint8_t {
  Sent = 0,           // handed to the driver's TX queue
  QueueFull = 1,      // ENOBUFS / EAGAIN: TX queue full; frame dropped, counted, not retried
  InterfaceDown = 2,  // ENETDOWN / ENXIO: the interface is down or gone
  BusOff = 3,         // the controller is bus-off (known from an error frame or the virtual bus)
  InvalidFrame = 4,   // identifier out of range, dlc above 8, or an error frame
  Failed = 5,         // any other errno (in SendResult::error_number)
};

[[nodiscard]] constexpr std::string_view to_string(SendStatus s) noexcept {
  switch (s) {
    case SendStatus::Sent:
      return "sent";
    case SendStatus::QueueFull:
      return "tx queue full";
    case SendStatus::InterfaceDown:
      return "interface down";
    case SendStatus::BusOff:
      return "bus-off";
    case SendStatus::InvalidFrame:
      return "invalid frame";
    case SendStatus::Failed:
      return "send failed";
  }
  return "?";
}

struct [[nodiscard]] SendResult {
  SendStatus status = SendStatus::Sent;
  int error_number = 0;  // errno behind QueueFull / InterfaceDown / Failed, 0 otherwise
  [[nodiscard]] bool sent() const noexcept { return status == SendStatus::Sent; }
};

struct [[nodiscard]] ReceiveResult {
  std::size_t count = 0;  // frames written to the caller's span (0: none before the deadline)
  // A port failure, not a timeout: CanError::kInterfaceDown (ENETDOWN), kNotOpen, or the errno.
  std::error_code error;
};

// One identifier the port lets through (CAN_RAW_FILTER entry with a full mask).
struct CanIdFilter {
  uint32_t id = 0;
  bool extended = false;
  friend bool operator==(const CanIdFilter&, const CanIdFilter&) = default;
};

// The most identifiers a port filters on: 8 modules × 3 objects + SYNC + SDO + EMCY + heartbeat
// fits comfortably; a fixed table keeps the ports free of allocation.
inline constexpr std::size_t kMaxFilters = 128;

// Monotonic counters since the port was opened. Snapshot; fields are read individually (each is
// exact, the set is not one instant).
struct CanPortCounters {
  uint64_t tx_frames = 0;          // sent
  uint64_t tx_queue_full = 0;      // ENOBUFS / EAGAIN: dropped, not retried
  uint64_t tx_interface_down = 0;  // ENETDOWN / ENXIO
  uint64_t tx_bus_off = 0;         // refused while bus-off
  uint64_t tx_invalid = 0;         // refused: not a sendable frame
  uint64_t tx_errors = 0;          // other send errors
  uint64_t rx_frames = 0;          // data/remote frames delivered to the caller
  uint64_t rx_error_frames = 0;    // error frames delivered (and decoded)
  uint64_t rx_kernel_drops = 0;  // frames the kernel dropped for a full socket queue (SO_RXQ_OVFL)
  uint64_t rx_unstamped = 0;     // frames without a kernel stamp (stamped with the read time)
  uint64_t rx_errors = 0;        // receive failures (ENETDOWN ...)
  uint64_t bus_off_events = 0;   // error frames announcing bus-off
  uint64_t restarts = 0;         // error frames announcing a controller restart
  uint64_t protocol_errors = 0;  // protocol violation error frames
  uint64_t controller_errors = 0;  // controller problem error frames
  uint64_t tx_timeouts = 0;        // TX timeout error frames
  uint64_t no_ack = 0;             // "no ACK on transmission" error frames
};

// What netlink (or the virtual bus) says about the interface.
struct CanInterfaceInfo {
  int ifindex = 0;
  bool up = false;                     // IFF_UP
  bool running = false;                // IFF_RUNNING (carrier)
  CanState state = CanState::Unknown;  // IFLA_CAN_STATE (Down when !up)
  uint32_t bitrate = 0;                // IFLA_CAN_BITTIMING.bitrate, bit/s (0: not configured)
  uint32_t sample_point = 0;           // tenths of a percent (875 = 87.5 %)
  uint32_t restart_ms = 0;             // IFLA_CAN_RESTART_MS (0: no automatic restart)
  uint32_t txqueuelen = 0;             // IFLA_TXQLEN: frames the kernel queues before ENOBUFS
  bool one_shot = false;               // IFLA_CAN_CTRLMODE: CAN_CTRLMODE_ONE_SHOT (no retransmit)
  bool error_counters_valid = false;   // IFLA_CAN_BERR_COUNTER present
  uint16_t tx_error_count = 0;
  uint16_t rx_error_count = 0;
};

class CanPort {
 public:
  virtual ~CanPort() = default;

  // ---- cycle thread -------------------------------------------------------------------------

  // Sends one frame without blocking. A full TX queue is counted and reported, the frame dropped:
  // the next cycle carries fresher data.
  virtual SendResult send(const CanFrame& frame) noexcept = 0;

  // Receives up to frames.size() frames into the caller's span. Waits until at least one frame is
  // there or CLOCK_MONOTONIC reaches deadline_ns (a deadline in the past makes it a single
  // non-blocking poll); once one frame is there, takes what is queued without waiting further.
  // Every frame carries rx_time_ns / rx_clock. Error frames (only the classes set with
  // set_error_mask) come in the same span with error == true; the port has already applied their
  // state change and counted them — decode_error_frame() gives the details.
  virtual ReceiveResult receive(std::span<CanFrame> frames, int64_t deadline_ns) noexcept = 0;

  // The controller state as last learned from an error frame or query_interface(). Any thread.
  [[nodiscard]] virtual CanState state() const noexcept = 0;

  // Any thread.
  [[nodiscard]] virtual CanPortCounters counters() const noexcept = 0;

  // ---- normal thread ------------------------------------------------------------------------

  // Lets exactly these identifiers through (an empty list: no data frames at all). Until the
  // first call every frame is received (the kernel's default). kTooManyFilters above kMaxFilters.
  [[nodiscard]] virtual std::error_code set_filters(std::span<const CanIdFilter> ids) noexcept = 0;

  // Error classes (err_class bits, can_error_frame.hpp) delivered as error frames. 0: none.
  [[nodiscard]] virtual std::error_code set_error_mask(uint32_t classes) noexcept = 0;

  // Reads the interface's state, bit rate and restart setting (SocketCAN: rtnetlink) and updates
  // state().
  [[nodiscard]] virtual Result<CanInterfaceInfo> query_interface() noexcept = 0;

  // Interface (SocketCAN) or port (virtual bus) name, for messages.
  [[nodiscard]] virtual std::string_view name() const noexcept = 0;
};

}  // namespace ds1928::canio
