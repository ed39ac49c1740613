// CRC-5 of endat.md §2, checked against a literal transcription of the shift-register rule.
#include <array>
#include <catch2/catch.hpp>
#include <cstdint>
#include <random>
#include <vector>

#include "endat/crc.hpp"

using namespace ds1928::endat;

namespace {

// The rule exactly as endat.md §2 states it, with five separate flip-flops. Deliberately not
// sharing any code with the implementation under test.
uint8_t reference_crc(const std::vector<int>& bits) {
  int ff0 = 1, ff1 = 1, ff2 = 1, ff3 = 1, ff4 = 1;
  for (int b : bits) {
    const int ex = ff4 ^ b;
    ff4 = ff3;
    ff3 = ff2 ^ ex;
    ff2 = ff1;
    ff1 = ff0 ^ ex;
    ff0 = ex;
  }
  // Inverted, ff4..ff0 as MSB..LSB.
  return static_cast<uint8_t>(((!ff4) << 4) | ((!ff3) << 3) | ((!ff2) << 2) | ((!ff1) << 1) |
                              (!ff0));
}

std::vector<int> msb_bits(uint64_t v, unsigned n) {
  std::vector<int> out;
  for (unsigned i = n; i-- > 0;) out.push_back(static_cast<int>((v >> i) & 1u));
  return out;
}

}  // namespace

TEST_CASE("CRC-5: vectors worked by hand from the shift register", "[endat][crc]") {
  // No bits: register stays 11111, inverted 00000.
  CHECK(crc5_bits(std::vector<uint8_t>{}) == 0x00);
  // One 0 bit: ex = 1 → ff4..ff0 = 1,0,1,0,1 → inverted 01010.
  CHECK(crc5_bits(std::vector<uint8_t>{0}) == 0x0A);
  // One 1 bit: ex = 0 → plain shift → 1,1,1,1,0 → inverted 00001.
  CHECK(crc5_bits(std::vector<uint8_t>{1}) == 0x01);
  // Bits 1,0: after '1' the register is 11110 (ff4..ff0); '0': ex = 1 →
  // ff4 = ff3 = 1, ff3 = ff2^1 = 0, ff2 = ff1 = 1, ff1 = ff0^1 = 1, ff0 = 1 → 10111 → 01000.
  CHECK(crc5_bits(std::vector<uint8_t>{1, 0}) == 0x08);
  // Bits 0,0: after '0' the register is 10101; '0': ex = 1 →
  // ff4 = 0, ff3 = 1^1 = 0, ff2 = 0, ff1 = 1^1 = 0, ff0 = 1 → 00001 → 11110.
  CHECK(crc5_bits(std::vector<uint8_t>{0, 0}) == 0x1E);
  // The same vectors through the reference transcription, so both agree with the hand work.
  CHECK(reference_crc({}) == 0x00);
  CHECK(reference_crc({0}) == 0x0A);
  CHECK(reference_crc({1}) == 0x01);
  CHECK(reference_crc({1, 0}) == 0x08);
  CHECK(reference_crc({0, 0}) == 0x1E);
}

TEST_CASE("CRC-5: bitwise implementation equals the flip-flop rule on random bit strings",
          "[endat][crc]") {
  std::mt19937_64 rng(0xE0DA7);
  for (int round = 0; round < 2000; ++round) {
    const auto n = static_cast<std::size_t>(rng() % 120);
    std::vector<int> bits(n);
    std::vector<uint8_t> bytes(n);
    for (std::size_t i = 0; i < n; ++i) bytes[i] = static_cast<uint8_t>(bits[i] = rng() & 1);
    REQUIRE(crc5_bits(bytes) == reference_crc(bits));
  }
}

TEST_CASE("CRC-5: table-driven bytewise equals bitwise on random data", "[endat][crc]") {
  std::mt19937_64 rng(42);
  for (int round = 0; round < 2000; ++round) {
    const auto n = static_cast<std::size_t>(rng() % 16);
    std::vector<uint8_t> data(n);
    Crc5 bitwise;
    std::vector<int> bits;
    for (auto& b : data) {
      b = static_cast<uint8_t>(rng());
      bitwise.push_msb_first(b, 8);
      for (int x : msb_bits(b, 8)) bits.push_back(x);
    }
    REQUIRE(crc5_bytes(data) == bitwise.value());
    REQUIRE(crc5_bytes(data) == reference_crc(bits));
  }
}

TEST_CASE("CRC-5: parameter reply covers address then value, MSB first", "[endat][crc]") {
  for (uint8_t address : {0x00, 0x0D, 0xA1, 0xFF}) {
    for (uint16_t value : {0x0000, 0x0025, 0x8000, 0xBEEF, 0xFFFF}) {
      std::vector<int> bits = msb_bits(address, 8);
      for (int b : msb_bits(value, 16)) bits.push_back(b);
      CHECK(crc5_parameter(address, value) == reference_crc(bits));
    }
  }
  // A generator with more than one term detects every single-bit error.
  const uint8_t good = crc5_parameter(0xA9, 0x1234);
  for (int bit = 0; bit < 16; ++bit) {
    CHECK(crc5_parameter(0xA9, static_cast<uint16_t>(0x1234 ^ (1 << bit))) != good);
  }
}

TEST_CASE("CRC-5: LSB-first position bits follow the wire order", "[endat][crc]") {
  // Position 0b0001 in 4 bits LSB first goes out as 1,0,0,0 preceded by F1 = 0.
  Crc5 crc;
  crc.push_bit(false);
  crc.push_lsb_first(0x1, 4);
  CHECK(crc.value() == reference_crc({0, 1, 0, 0, 0}));
}
