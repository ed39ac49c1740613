#include "capture/can_record.hpp"

#include <cinttypes>
#include <cstdio>

namespace ds1928::capture {

SocketCanBytes socketcan_bytes(const canio::CanFrame& frame) noexcept {
  SocketCanBytes b{};
  uint32_t word = 0;
  uint8_t length = 0;
  if (frame.error) {
    word = kCanErrFlag | (frame.id & 0x1FFFFFFFU);
    length = kCanErrDlc;
  } else {
    word = (frame.extended ? kCanEffFlag | (frame.id & canio::kMaxExtendedId)
                           : frame.id & canio::kMaxStandardId) |
           (frame.rtr ? kCanRtrFlag : 0);
    length = frame.dlc <= canio::kMaxDlc ? frame.dlc : canio::kMaxDlc;
  }
  b[0] = static_cast<uint8_t>(word >> 24);
  b[1] = static_cast<uint8_t>(word >> 16);
  b[2] = static_cast<uint8_t>(word >> 8);
  b[3] = static_cast<uint8_t>(word);
  b[4] = length;
  // A remote frame's length is the requested one; it carries no data.
  if (!frame.rtr)
    for (std::size_t i = 0; i < length; ++i) b[8 + i] = frame.data[i];
  return b;
}

std::string candump_line(int64_t realtime_ns, std::string_view interface,
                         std::span<const uint8_t, kSocketCanFrameSize> f) {
  const uint32_t word = static_cast<uint32_t>(f[0]) << 24 | static_cast<uint32_t>(f[1]) << 16 |
                        static_cast<uint32_t>(f[2]) << 8 | f[3];
  const uint8_t length = f[4] <= canio::kMaxDlc ? f[4] : canio::kMaxDlc;
  char head[48];
  const int64_t us = realtime_ns / 1000;
  std::snprintf(head, sizeof head, "(%010" PRId64 ".%06" PRId64 ") ", us / 1'000'000,
                us % 1'000'000);
  std::string line = head;
  line.append(interface);
  char id[16];
  if (word & kCanErrFlag)
    std::snprintf(id, sizeof id, " %08" PRIX32 "#", word & (kCanErrFlag | 0x1FFFFFFFU));
  else if (word & kCanEffFlag)
    std::snprintf(id, sizeof id, " %08" PRIX32 "#", word & 0x1FFFFFFFU);
  else
    std::snprintf(id, sizeof id, " %03" PRIX32 "#", word & 0x7FFU);
  line += id;
  if (!(word & kCanErrFlag) && (word & kCanRtrFlag)) {
    line += 'R';
  } else {
    static constexpr char kHex[] = "0123456789ABCDEF";
    for (std::size_t i = 0; i < length; ++i) {
      line += kHex[f[8 + i] >> 4];
      line += kHex[f[8 + i] & 0xF];
    }
  }
  line += '\n';
  return line;
}

}  // namespace ds1928::capture
