#include "endat/crc.hpp"

#include <array>

namespace ds1928::endat {
namespace {

// The 5-bit register is kept left-aligned in a byte (bits 7..3) so a whole input byte can be
// XORed into it; the table holds the register after eight shift steps.
constexpr std::array<uint8_t, 256> make_table() noexcept {
  std::array<uint8_t, 256> table{};
  constexpr uint8_t poly = static_cast<uint8_t>(kCrc5Polynomial << 3);
  for (unsigned i = 0; i < 256; ++i) {
    uint8_t r = static_cast<uint8_t>(i);
    for (int k = 0; k < 8; ++k) {
      r = (r & 0x80u) != 0 ? static_cast<uint8_t>((r << 1) ^ poly) : static_cast<uint8_t>(r << 1);
    }
    table[i] = r;
  }
  return table;
}
constexpr auto kTable = make_table();

}  // namespace

uint8_t crc5_bits(std::span<const uint8_t> bits) noexcept {
  Crc5 crc;
  for (uint8_t b : bits) crc.push_bit(b != 0);
  return crc.value();
}

uint8_t crc5_bytes(std::span<const uint8_t> bytes) noexcept {
  uint8_t r = static_cast<uint8_t>(kCrc5Init << 3);
  for (uint8_t byte : bytes) r = kTable[static_cast<uint8_t>(r ^ byte)];
  return static_cast<uint8_t>(~(r >> 3) & 0x1Fu);
}

uint8_t crc5_parameter(uint8_t address, uint16_t value) noexcept {
  const std::array<uint8_t, 3> bytes{address, static_cast<uint8_t>(value >> 8),
                                     static_cast<uint8_t>(value & 0xFF)};
  return crc5_bytes(bytes);
}

}  // namespace ds1928::endat
