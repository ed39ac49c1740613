// Bits on the wire: the frame formula checked against a bit-level model of a CAN 2.0A frame
// (stuffing counted on real bit patterns), and the cycle budget's arithmetic.
#include "canio/bit_budget.hpp"

#include <catch2/catch.hpp>
#include <random>
#include <vector>

using namespace ds1928::canio;

namespace {

// Number of stuff bits the transmitter inserts into `bits` (CAN 2.0 §5: after five consecutive
// equal bits a complementary bit, which itself counts towards the next run).
uint32_t stuff_bits(const std::vector<int>& bits) {
  uint32_t stuffed = 0;
  int run_value = -1, run = 0;
  for (int b : bits) {
    if (b == run_value) {
      ++run;
    } else {
      run_value = b;
      run = 1;
    }
    if (run == 5) {
      ++stuffed;
      run_value = !b;  // the stuff bit
      run = 1;
    }
  }
  return stuffed;
}

// SOF..CRC of a standard data frame: SOF(0) id(11) RTR(0) IDE(0) r0(0) DLC(4) data CRC(15).
std::vector<int> stuffable_bits(uint32_t id, const std::vector<uint8_t>& data) {
  std::vector<int> bits{0};
  for (int i = 10; i >= 0; --i) bits.push_back((id >> i) & 1);
  bits.insert(bits.end(), {0, 0, 0});
  for (int i = 3; i >= 0; --i) bits.push_back((data.size() >> i) & 1);
  for (uint8_t byte : data)
    for (int i = 7; i >= 0; --i) bits.push_back((byte >> i) & 1);
  // CRC-15 (polynomial 0x4599) over the bits so far.
  uint16_t crc = 0;
  for (int b : bits) {
    const int next = b ^ ((crc >> 14) & 1);
    crc = static_cast<uint16_t>((crc << 1) & 0x7FFF);
    if (next) crc ^= 0x4599;
  }
  for (int i = 14; i >= 0; --i) bits.push_back((crc >> i) & 1);
  return bits;
}

}  // namespace

TEST_CASE("frame bits: 47 + 8n nominal, 135 for 8 bytes worst case", "[canio][budget]") {
  CHECK(frame_bits(0).nominal == 47);
  CHECK(frame_bits(0).worst_case == 55);  // 47 + floor(33 / 4)
  CHECK(frame_bits(8).nominal == 111);
  CHECK(frame_bits(8).worst_case == 135);
  CHECK(frame_bits(7).worst_case == 103 + 22);
  CHECK(frame_bits(12).nominal == 111);  // a classic frame never carries more than 8
  CHECK(frame_bits(8, true).nominal == 131);
  CHECK(frame_bits(8, true).worst_case == 131 + 29);  // floor((54 + 64 - 1) / 4)
}

TEST_CASE("worst-case stuffing bound holds for real frames and is reached", "[canio][budget]") {
  std::mt19937_64 rng(0xB175);
  for (uint32_t n = 0; n <= 8; ++n) {
    const auto bound = frame_bits(n).worst_case - frame_bits(n).nominal;
    uint32_t worst_seen = 0;
    for (int i = 0; i < 3000; ++i) {
      std::vector<uint8_t> data(n);
      // Mostly long runs (0x00/0xFF and alternations of them) to provoke stuffing.
      for (auto& b : data)
        b = (rng() & 3) == 0 ? static_cast<uint8_t>(rng()) : ((rng() & 1) ? 0xFF : 0x00);
      const auto id = static_cast<uint32_t>(rng() & 1 ? (rng() & 0x7FF) : (rng() & 1 ? 0 : 0x7FF));
      const uint32_t s = stuff_bits(stuffable_bits(id, data));
      REQUIRE(s <= bound);
      worst_seen = std::max(worst_seen, s);
    }
    // A stuff-free model would see none; this one must see stuffing in long-run frames.
    if (n >= 2) CHECK(worst_seen >= bound / 2);
  }
  // The bound is reached: 11111 0000 1111 0000 ... stuffs after 5 bits, then after every 4
  // (each stuff bit starts the next run), floor((L - 1) / 4) stuff bits for L bits.
  for (uint32_t len = 1; len < 120; ++len) {
    std::vector<int> bits;
    for (uint32_t i = 0; i < len; ++i) bits.push_back(i < 5 ? 1 : (((i - 5) / 4) % 2 == 0 ? 0 : 1));
    REQUIRE(stuff_bits(bits) == (len - 1) / 4);
  }
}

TEST_CASE("cycle budget: 3 frames per module, optional SYNC", "[canio][budget]") {
  CycleLoad one;
  one.modules = 1;
  one.bitrate = 500'000;
  auto b = cycle_budget(one);
  CHECK(b.frames == 3);
  CHECK(b.bits_nominal == 333);
  CHECK(b.bits_worst_case == 405);
  CHECK(b.time_worst_case_ns == 810'000);  // 405 bits at 2 µs
  CHECK(b.time_nominal_ns == 666'000);
  one.sync = true;
  b = cycle_budget(one);
  CHECK(b.frames == 4);
  CHECK(b.bits_worst_case == 460);
  CycleLoad eight = one;
  eight.modules = 8;
  eight.bitrate = 1'000'000;
  b = cycle_budget(eight);
  CHECK(b.frames == 25);
  CHECK(b.bits_worst_case == 8 * 405 + 55);
  CHECK(b.time_worst_case_ns == (8 * 405 + 55) * 1000);
}

TEST_CASE("check_cycle says whether and by how much the cycle fits", "[canio][budget]") {
  CycleLoad load;
  load.modules = 1;
  load.bitrate = 500'000;
  auto fit = check_cycle(load, 2'000'000);
  CHECK(fit.fits);
  CHECK(fit.margin_ns == 2'000'000 - 810'000);
  CHECK(fit.load_worst_case == Approx(0.405));
  load.modules = 3;
  fit = check_cycle(load, 2'000'000);
  CHECK_FALSE(fit.fits);    // 3 × 810 µs = 2.43 ms
  CHECK(fit.fits_nominal);  // 3 × 666 µs = 1.998 ms
  CHECK(fit.margin_ns == -430'000);
  CHECK_FALSE(check_cycle(load, 0).fits);
  load.bitrate = 0;
  CHECK(cycle_budget(load).time_worst_case_ns == 0);
}
