// Flatstream wire format (datasheet X20DS1928 §11.9): control bytes, sequence registers, the
// layout options and the engine's fixed limits. Pure constants and bit twiddling.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "x20ds1928/module_image.hpp"

namespace ds1928::flatstream {

// ---- Limits of this engine (storage is fixed; nothing grows at run time) --------------------
inline constexpr std::size_t kMinMtu = 2;  // datasheet says 3 in theory; 2 still carries 1 byte
inline constexpr std::size_t kMaxMtu = kMaxFlatstreamMtu;  // 27
// Longest message one direction carries. EnDat commands and replies are far shorter; 512 leaves
// room for a memory-block transfer and is what both roles' storage is sized for.
inline constexpr std::size_t kMaxMessageSize = 512;
// Messages per direction that may be queued (submitted, not yet reported) or received (not
// yet taken). A message keeps its send slot until acknowledged, so the depth must cover what is
// in flight: 7 sequences × up to 3 short messages per 27-byte MTU, plus what waits behind them.
inline constexpr std::size_t kQueueDepth = 32;
inline constexpr uint8_t kMaxForward = 7;  // 3-bit counter: at most 7 unacknowledged sequences
inline constexpr uint8_t kMaxSegmentLength = 63;

// ---- Control byte ------------------------------------------------------------------------
namespace cb {
inline constexpr uint8_t kLengthMask = 0x3F;  // SegmentLength
inline constexpr uint8_t kNextCbPos = 0x40;   // 1: next control byte follows this segment directly
inline constexpr uint8_t kMessageEnd = 0x80;  // MessageEndBit
inline constexpr uint8_t kIdle = 0x00;        // "C0": nothing (more) in this MTU

[[nodiscard]] constexpr uint8_t make(uint8_t length, bool next_cb_pos, bool message_end) noexcept {
  return static_cast<uint8_t>((length & kLengthMask) | (next_cb_pos ? kNextCbPos : 0) |
                              (message_end ? kMessageEnd : 0));
}
}  // namespace cb

// ---- FlatstreamMode: layout of the send array ---------------------------------------------
// The module sends the input direction in the configured layout; every receiver accepts all four.
enum class Layout : uint8_t {
  Default = 0,            // one segment per sequence, segment < MTU, tail of a message's MTU wasted
  MultiSegmentMtu = 1,    // bit 0: fill the MTU with the following control bytes and segments
  LargeSegments = 2,      // bit 1: segments up to 63 bytes, spanning sequences
  LargeMultiSegment = 3,  // both
};
[[nodiscard]] constexpr bool multi_segment(Layout l) noexcept {
  return (static_cast<uint8_t>(l) & 1) != 0;
}
[[nodiscard]] constexpr bool large_segments(Layout l) noexcept {
  return (static_cast<uint8_t>(l) & 2) != 0;
}
[[nodiscard]] constexpr const char* to_string(Layout l) noexcept {
  switch (l) {
    case Layout::Default:
      return "default";
    case Layout::MultiSegmentMtu:
      return "multi-segment";
    case Layout::LargeSegments:
      return "large";
    case Layout::LargeMultiSegment:
      return "large+multi";
  }
  return "?";
}

// ---- Sequence registers --------------------------------------------------------------------
// OutputSequence (CPU writes) and InputSequence (module writes) share one shape: the low nibble
// belongs to the direction this side sends (counter + SyncBit), the high nibble acknowledges the
// direction it receives (ack + SyncAck). The nibbles pair crosswise with the peer's register.
struct SequenceRegister {
  uint8_t counter = 0;    // bits 0-2: OutputSequenceCounter / InputSequenceCounter
  bool sync_bit = false;  // bit 3: OutputSyncBit / InputSyncBit
  uint8_t ack = 0;        // bits 4-6: InputSequenceAck / OutputSequenceAck
  bool sync_ack = false;  // bit 7: InputSyncAck / OutputSyncAck

  [[nodiscard]] static constexpr SequenceRegister decode(uint8_t raw) noexcept {
    return {static_cast<uint8_t>(raw & 0x07), (raw & 0x08) != 0,
            static_cast<uint8_t>((raw >> 4) & 0x07), (raw & 0x80) != 0};
  }
  [[nodiscard]] constexpr uint8_t encode() const noexcept {
    return static_cast<uint8_t>((counter & 0x07) | (sync_bit ? 0x08 : 0) | ((ack & 0x07) << 4) |
                                (sync_ack ? 0x80 : 0));
  }
  friend constexpr bool operator==(const SequenceRegister&, const SequenceRegister&) = default;
};

// Distance from `from` to `to` on the 3-bit counter ring.
[[nodiscard]] constexpr uint8_t seq_distance(uint8_t from, uint8_t to) noexcept {
  return static_cast<uint8_t>((to - from) & 0x07);
}
[[nodiscard]] constexpr uint8_t seq_next(uint8_t c, uint8_t n = 1) noexcept {
  return static_cast<uint8_t>((c + n) & 0x07);
}

using MtuBytes = std::array<uint8_t, kMaxMtu>;

}  // namespace ds1928::flatstream
