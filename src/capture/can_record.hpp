// CAN frames as a capture stores them: the 16-byte SocketCAN form of LINKTYPE_CAN_SOCKETCAN
// (struct can_frame with the identifier word in network byte order, as the link type's
// specification demands), and the can-utils log line (`candump -L`, replayable with canplayer).
// Pure codecs.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "can/can_frame.hpp"

namespace ds1928::capture {

inline constexpr std::size_t kSocketCanFrameSize = 16;
// Flag bits of the SocketCAN identifier word (linux/can.h).
inline constexpr uint32_t kCanEffFlag = 0x80000000U;
inline constexpr uint32_t kCanRtrFlag = 0x40000000U;
inline constexpr uint32_t kCanErrFlag = 0x20000000U;
inline constexpr uint8_t kCanErrDlc = 8;  // error frames always carry 8 data bytes

using SocketCanBytes = std::array<uint8_t, kSocketCanFrameSize>;

// Identifier word (with EFF/RTR/ERR flags), length, 3 bytes of padding/reserved, 8 data bytes
// (zero beyond the length). An error frame: CAN_ERR_FLAG | its class bits, length 8.
[[nodiscard]] SocketCanBytes socketcan_bytes(const canio::CanFrame& frame) noexcept;

// "(1700000000.123456) can0 123#11223344" for a frame in SocketCAN form: standard ids as 3 hex
// digits, extended ids and error frames as 8 (error frames with CAN_ERR_FLAG, as candump writes
// them), a remote frame as "R". `realtime_ns`: nanoseconds since the epoch (printed in µs).
[[nodiscard]] std::string candump_line(int64_t realtime_ns, std::string_view interface,
                                       std::span<const uint8_t, kSocketCanFrameSize> frame);

}  // namespace ds1928::capture
