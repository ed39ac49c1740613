// One classic CAN 2.0 frame as the port layer moves it: identifier (11 or 29 bit), RTR and
// error-frame flags, 0..8 data bytes, and the time it was received. Plain value type, fixed size,
// no allocation; CAN FD is deliberately absent (the CAN-I/O bus controller is classic CAN).
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <span>

namespace ds1928::canio {

inline constexpr uint32_t kMaxStandardId = 0x7FF;        // CAN 2.0A, 11 bit
inline constexpr uint32_t kMaxExtendedId = 0x1FFF'FFFF;  // CAN 2.0B, 29 bit
inline constexpr uint8_t kMaxDlc = 8;

// Which clock produced a frame's rx_time_ns (always expressed on CLOCK_MONOTONIC).
enum class RxClock : uint8_t {
  None = 0,            // no reception time (frame built locally, or to be sent)
  KernelSoftware = 1,  // kernel software RX stamp (SO_TIMESTAMPING / SO_TIMESTAMPNS), moved
                       // from CLOCK_REALTIME to CLOCK_MONOTONIC
  KernelHardware =
      2,           // controller's hardware stamp (SOF_TIMESTAMPING_RAW_HARDWARE), moved
                   // likewise; not produced by the current ports, kept for controllers that stamp
  ReadTime = 3,    // no kernel stamp arrived: CLOCK_MONOTONIC when the frame was read
  VirtualBus = 4,  // the virtual test bus' clock (real CLOCK_MONOTONIC or a test's fake clock)
};

[[nodiscard]] constexpr const char* to_string(RxClock c) noexcept {
  switch (c) {
    case RxClock::None:
      return "none";
    case RxClock::KernelSoftware:
      return "kernel-software";
    case RxClock::KernelHardware:
      return "kernel-hardware";
    case RxClock::ReadTime:
      return "read-time";
    case RxClock::VirtualBus:
      return "virtual-bus";
  }
  return "?";
}

struct CanFrame {
  // 11-bit (extended == false) or 29-bit identifier, without flag bits. For an error frame
  // (error == true) it holds the SocketCAN error class bits (CAN_ERR_* of linux/can/error.h);
  // decode it with decode_error_frame() (can_error_frame.hpp).
  uint32_t id = 0;
  bool extended = false;
  bool rtr = false;    // remote transmission request: dlc is the requested length, no data
  bool error = false;  // error frame reported by the controller/driver, never sent on the wire
  uint8_t dlc = 0;     // 0..8 data bytes
  std::array<uint8_t, 8> data{};
  int64_t rx_time_ns = 0;  // CLOCK_MONOTONIC reception instant; 0 when rx_clock == None
  RxClock rx_clock = RxClock::None;

  [[nodiscard]] std::span<const uint8_t> payload() const noexcept {
    return {data.data(), rtr ? 0u : (dlc <= kMaxDlc ? dlc : kMaxDlc)};
  }
};

// A data frame with a standard identifier; bytes past 8 are ignored (callers validate lengths).
[[nodiscard]] inline CanFrame make_standard_frame(uint32_t id,
                                                  std::span<const uint8_t> bytes) noexcept {
  CanFrame f;
  f.id = id & kMaxStandardId;
  f.dlc = static_cast<uint8_t>(bytes.size() < kMaxDlc ? bytes.size() : kMaxDlc);
  if (f.dlc != 0) std::memcpy(f.data.data(), bytes.data(), f.dlc);
  return f;
}

// True when the frame can go on the wire: identifier within its format, dlc 0..8, not an error
// frame.
[[nodiscard]] constexpr bool is_sendable(const CanFrame& f) noexcept {
  return !f.error && f.dlc <= kMaxDlc && f.id <= (f.extended ? kMaxExtendedId : kMaxStandardId);
}

// Same identifier, format, flags and payload (reception time ignored).
[[nodiscard]] inline bool same_content(const CanFrame& a, const CanFrame& b) noexcept {
  if (a.id != b.id || a.extended != b.extended || a.rtr != b.rtr || a.error != b.error ||
      a.dlc != b.dlc)
    return false;
  const auto n = a.rtr ? 0u : (a.dlc <= kMaxDlc ? a.dlc : kMaxDlc);
  return std::memcmp(a.data.data(), b.data.data(), n) == 0;
}

}  // namespace ds1928::canio
