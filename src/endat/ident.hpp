// Encoder identification from the manufacturer parameter words (MRS 0xA1/0xA3/0xA5, global word
// number = page × 16 + word; endat.md §4). The module mirrors words 4..47 into ParamManuf_04..47.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "endat/command.hpp"
#include "endat/error.hpp"

namespace ds1928::endat {

inline constexpr std::size_t kManufacturerWords = 48;
using ManufacturerWords = std::array<uint16_t, kManufacturerWords>;

// Global word numbers.
namespace manuf_word {
inline constexpr unsigned kMask0 = 4;  // masks 0..3: words 4..7
inline constexpr unsigned kEnDatVersion = 8;
inline constexpr unsigned kPositionBits = 13;  // bits 5..0
inline constexpr unsigned kEncoderType = 14;   // bit 15: 1 rotary, 0 linear
inline constexpr unsigned kSignalPeriodsLow = 15;
inline constexpr unsigned kSignalPeriodsHigh = 16;
inline constexpr unsigned kRevolutions = 17;  // 0 = singleturn
inline constexpr unsigned kStepsLow = 20;
inline constexpr unsigned kStepsHigh = 21;
inline constexpr unsigned kIdText = 24;  // two ASCII characters, first in the high byte
inline constexpr unsigned kIdLow = 25;   // 32-bit binary ID, low word
inline constexpr unsigned kIdHigh = 26;
inline constexpr unsigned kSerial0 = 27;  // low byte ASCII prefix; high byte binary bits 7..0
inline constexpr unsigned kSerial1 = 28;  // binary bits 23..8
inline constexpr unsigned kSerial2 = 29;  // low byte binary bits 31..24; high byte ASCII suffix
inline constexpr unsigned kWarningsSupported = 36;
inline constexpr unsigned kCommandSet = 37;  // bit 0 = 1 and bit 1 = 0: EnDat 2.2 command set
inline constexpr unsigned kChecksum = 47;
}  // namespace manuf_word

// MRS code of the page holding a global manufacturer word.
[[nodiscard]] constexpr uint8_t manufacturer_page_mrs(unsigned global_word) noexcept {
  return static_cast<uint8_t>(0xA1 + 2 * (global_word / 16));
}

enum class EncoderType : uint8_t { Linear = 0, Rotary = 1 };

struct IdNumber {
  char text[2] = {' ', ' '};  // ASCII part (word 24)
  uint32_t binary = 0;        // words 25..26
  // "1081302-01" style: binary, then '-' and the ASCII part when it is printable and not blank.
  [[nodiscard]] std::string to_string() const;
};

struct SerialNumber {
  char prefix = ' ';  // low byte of word 27
  uint32_t binary = 0;
  char suffix = ' ';  // high byte of word 29
  [[nodiscard]] std::string to_string() const;
};

struct Identification {
  uint16_t version_word = 0;      // word 8, raw (its coding is not in the sources)
  uint16_t command_set_word = 0;  // word 37, raw
  CommandSet command_set = CommandSet::EnDat21;
  EncoderType type = EncoderType::Rotary;
  unsigned position_bits = 0;   // clock pulses for the position value
  uint32_t signal_periods = 0;  // per revolution (rotary)
  uint16_t revolutions = 0;     // distinguishable revolutions, 0 = singleturn
  uint32_t steps_per_revolution = 0;
  IdNumber id;
  SerialNumber serial;
  uint16_t warnings_supported = 0;
  uint16_t checksum = 0;  // word 47, raw

  [[nodiscard]] bool multiturn() const noexcept { return revolutions != 0; }
};

// Command set from word 37: bit 0 set and bit 1 clear → EnDat 2.2.
[[nodiscard]] CommandSet command_set_from_word(uint16_t word37) noexcept;

// `words` are global words 0..47; words 0..3 are not used (the module's registers ParamManuf_04..47
// start at 4, so a daemon passes zeros there). Decodes and checks consistency: position bits 1..48;
// for a rotary encoder, the steps per revolution × revolutions must fit in the position bits.
// Error: invalid_identification.
[[nodiscard]] Result<Identification> decode_identification(
    std::span<const uint16_t, kManufacturerWords> words) noexcept;

// Inverse of decode_identification for the words it covers (the simulated encoder uses it).
// Words it does not cover are left as they are in `words`.
void encode_identification(const Identification& ident,
                           std::span<uint16_t, kManufacturerWords> words) noexcept;

// Number of bits needed for values 0..n-1 (ceil(log2 n)), 0 for n <= 1.
[[nodiscard]] unsigned bits_for(uint64_t n) noexcept;

}  // namespace ds1928::endat
