// EnDat CRC-5 (endat.md §2). The reference is the encoder's shift register: five flip-flops
// ff0..ff4 preset to 1; per bit b in wire order ex = ff4 ^ b, ff4 = ff3, ff3 = ff2 ^ ex,
// ff2 = ff1, ff1 = ff0 ^ ex, ff0 = ex; the CRC is the inverted register read ff4..ff0.
// Crc5 keeps the register as an integer whose bit i is ff_i, so one step is a shift left and an
// XOR with 0x0B (x^5 + x^3 + x + 1) when ex is set. crc5_bytes() is a table-driven equivalent
// for whole bytes sent MSB first (parameter replies: address byte then value high, value low).
#pragma once

#include <cstdint>
#include <span>

namespace ds1928::endat {

inline constexpr uint8_t kCrc5Polynomial = 0x0B;
inline constexpr uint8_t kCrc5Init = 0x1F;

class Crc5 {
 public:
  constexpr void push_bit(bool bit) noexcept {
    const bool ex = (((reg_ >> 4) & 1u) != 0) != bit;
    reg_ = static_cast<uint8_t>(((reg_ << 1) & 0x1Eu) ^ (ex ? kCrc5Polynomial : 0u));
  }
  // `count` bits of `value`, most significant of them first.
  constexpr void push_msb_first(uint64_t value, unsigned count) noexcept {
    for (unsigned i = count; i-- > 0;) push_bit(((value >> i) & 1u) != 0);
  }
  // `count` bits of `value`, least significant first (EnDat position values).
  constexpr void push_lsb_first(uint64_t value, unsigned count) noexcept {
    for (unsigned i = 0; i < count; ++i) push_bit(((value >> i) & 1u) != 0);
  }
  [[nodiscard]] constexpr uint8_t register_state() const noexcept { return reg_; }
  [[nodiscard]] constexpr uint8_t value() const noexcept {
    return static_cast<uint8_t>(~reg_ & 0x1Fu);
  }

 private:
  uint8_t reg_ = kCrc5Init;
};

// CRC of `bits` (each element 0 or 1, wire order).
[[nodiscard]] uint8_t crc5_bits(std::span<const uint8_t> bits) noexcept;

// CRC of whole bytes sent MSB first, table-driven (one lookup per byte).
[[nodiscard]] uint8_t crc5_bytes(std::span<const uint8_t> bytes) noexcept;

// CRC of a parameter reply: 8-bit address then 16-bit value, both MSB first.
[[nodiscard]] uint8_t crc5_parameter(uint8_t address, uint16_t value) noexcept;

}  // namespace ds1928::endat
