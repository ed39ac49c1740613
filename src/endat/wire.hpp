// EnDat frames on the wire (endat.md §1–§2) as bit sequences, for the two ends the project
// simulates: the module firmware (master) and the encoder (slave). Pure: bits in, values out.
//
// Master → encoder: 6 mode bits, then for commands with a parameter field 8 address/MRS bits
// and 16 parameter bits, all MSB first. The master sends no CRC; the encoder's echo is the check.
// Encoder → master:
//   parameter reply:   start bit, address (8, MSB first), value (16, MSB first), CRC (5)
//   position 2.1:      start bit, F1, position (n bits, LSB first), CRC over F1 + position
//   position 2.2:      start bit, F1, F2, position, CRC over F1 + F2 + position, then for each
//                      selected additional information: status (8), data (16), CRC over both
// An empty frame means the encoder did not answer (no start bit).
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "endat/command.hpp"
#include "endat/error.hpp"

namespace ds1928::endat::wire {

inline constexpr std::size_t kMaxFrameBits = 160;
inline constexpr unsigned kMaxPositionBits = 48;

class BitFrame {
 public:
  void push_bit(bool bit) noexcept {
    if (size_ < kMaxFrameBits) {
      bits_[size_++] = bit ? 1 : 0;
    } else {
      overflow_ = true;
    }
  }
  void push_msb_first(uint64_t value, unsigned count) noexcept {
    for (unsigned i = count; i-- > 0;) push_bit(((value >> i) & 1u) != 0);
  }
  void push_lsb_first(uint64_t value, unsigned count) noexcept {
    for (unsigned i = 0; i < count; ++i) push_bit(((value >> i) & 1u) != 0);
  }
  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] bool empty() const noexcept { return size_ == 0; }
  [[nodiscard]] bool overflow() const noexcept { return overflow_; }
  [[nodiscard]] bool bit(std::size_t i) const noexcept { return i < size_ && bits_[i] != 0; }
  void flip(std::size_t i) noexcept {
    if (i < size_) bits_[i] ^= 1u;
  }
  void truncate(std::size_t n) noexcept {
    if (n < size_) size_ = n;
  }

  // Reads `count` bits at `pos` and advances it; false (and `pos` unchanged) past the end.
  [[nodiscard]] bool read_msb_first(std::size_t& pos, unsigned count, uint64_t& out) const noexcept;
  [[nodiscard]] bool read_lsb_first(std::size_t& pos, unsigned count, uint64_t& out) const noexcept;

  friend bool operator==(const BitFrame& a, const BitFrame& b) noexcept {
    if (a.size_ != b.size_) return false;
    for (std::size_t i = 0; i < a.size_; ++i) {
      if (a.bits_[i] != b.bits_[i]) return false;
    }
    return true;
  }

 private:
  std::array<uint8_t, kMaxFrameBits> bits_{};
  std::size_t size_ = 0;
  bool overflow_ = false;
};

// Mode commands (6 bits as sent). EnDat 2.1 codes are three bits and their inverse; the 2.2
// additions repeat their three bits.
enum class Mode : uint8_t {
  SendPosition = 0x07,
  SelectMemoryArea = 0x0E,
  ReceiveParameter = 0x1C,
  SendParameter = 0x23,
  ReceiveReset = 0x2A,
  SendTestValues = 0x15,
  ReceiveTestCommand = 0x31,
  PositionAddInfo = 0x38,
  PositionAddInfoSelectMemory = 0x09,
  PositionAddInfoReceiveParameter = 0x1B,
  PositionAddInfoSendParameter = 0x24,
  PositionAddInfoErrorReset = 0x2D,
  PositionAddInfoTestCommand = 0x36,
  CommunicationCommand = 0x12,
};

[[nodiscard]] std::optional<Mode> mode_from_bits(uint8_t six_bits) noexcept;
[[nodiscard]] bool is_endat22_mode(Mode m) noexcept;
// Modes followed by 8 address + 16 parameter bits from the master.
[[nodiscard]] bool has_parameter_field(Mode m) noexcept;
// Modes the encoder answers with a position frame (2.1 or 2.2 format).
[[nodiscard]] bool answers_with_position(Mode m) noexcept;

struct MasterFrame {
  Mode mode = Mode::SendPosition;
  uint8_t address = 0;     // parameter number or MRS code
  uint16_t parameter = 0;  // value, or block number for a memory-area selection
};

[[nodiscard]] BitFrame encode_master_frame(const MasterFrame& f) noexcept;
// Errors: frame_length, invalid_mode.
[[nodiscard]] Result<MasterFrame> decode_master_frame(const BitFrame& bits) noexcept;

struct ParameterReply {
  uint8_t address = 0;
  uint16_t value = 0;
};
inline constexpr std::size_t kParameterReplyBits = 1 + 8 + 16 + 5;

[[nodiscard]] BitFrame encode_parameter_reply(const ParameterReply& r) noexcept;
// Errors: no_response, frame_length, crc_mismatch.
[[nodiscard]] Result<ParameterReply> decode_parameter_reply(const BitFrame& bits) noexcept;

struct AdditionalInfo {
  uint8_t status = 0;  // bit 7 warning, bit 6 reference mark, bit 5 busy, bits 4..0 which AI
  uint16_t data = 0;
  [[nodiscard]] bool warning() const noexcept { return (status & 0x80) != 0; }
  [[nodiscard]] bool busy() const noexcept { return (status & 0x20) != 0; }
  [[nodiscard]] uint8_t which() const noexcept { return status & 0x1F; }
};
inline constexpr std::size_t kAdditionalInfoBits = 8 + 16 + 5;

// What the master expects in a position frame.
struct PositionFormat {
  CommandSet set = CommandSet::EnDat22;
  unsigned position_bits = 0;  // 1..48
  bool ai1 = false;            // 2.2 only
  bool ai2 = false;            // 2.2 only
  [[nodiscard]] std::size_t frame_bits() const noexcept;
};

struct PositionReply {
  bool f1 = false;  // error bit
  bool f2 = true;   // 2.2: inverse of F1
  uint64_t position = 0;
  std::optional<AdditionalInfo> ai1;
  std::optional<AdditionalInfo> ai2;
  [[nodiscard]] bool error() const noexcept { return f1; }
};

// `r.ai1/ai2` are sent when present (2.2 only); the format's flags are ignored when encoding.
[[nodiscard]] BitFrame encode_position_reply(const PositionReply& r, CommandSet set,
                                             unsigned position_bits) noexcept;
// Errors: no_response, frame_length, crc_mismatch (position or either AI), f2_not_inverted.
[[nodiscard]] Result<PositionReply> decode_position_reply(const BitFrame& bits,
                                                          const PositionFormat& format) noexcept;

}  // namespace ds1928::endat::wire
