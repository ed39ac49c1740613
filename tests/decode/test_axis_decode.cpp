// Axis decoding against values computed by hand from the datasheet's position format
// (X20DS1928.md §4) and NetTime (§8).
#include <catch2/catch.hpp>

#include "core/axis_sample.hpp"

using namespace ds1928;

namespace {
AxisIo image(uint64_t raw, int8_t pos_cycle = 0, uint32_t pos_time = 0, bool fresh = true) {
  AxisIo io;
  io.inputs.position_hw = static_cast<uint32_t>(raw >> 32);
  io.inputs.position_lw = static_cast<uint32_t>(raw);
  io.inputs.pos_cycle = pos_cycle;
  io.inputs.pos_time_us = pos_time;
  io.inputs_fresh = fresh;
  io.rx_time_ns = 777;
  return io;
}
const NetTimeRef kRef{1'000'000, 5'000'000'000, true};
}  // namespace

TEST_CASE("position splits into whole periods and a 16-bit fraction", "[decode]") {
  AxisDecodeState st;
  // 65538 whole periods and a quarter period (0x4000 = 90°).
  const auto s = decode_axis(image(0x0000'0001'0002'4000), {}, kRef, st);
  CHECK(s.position_raw == 0x0000'0001'0002'4000ULL);
  CHECK(s.periods == 65538);
  CHECK(s.fraction == 0x4000);
  CHECK(s.fraction_valid);
  CHECK(s.position_sdc == 0x0002'4000);
}

TEST_CASE("signed format sign-extends the whole periods, the SDC view is the low 32 bits signed",
          "[decode]") {
  AxisDecodeState st;
  AxisDecodeParams signed_params;
  signed_params.signed_format = true;
  // Half a period below zero: -1 whole period + 0x8000 (180°).
  const auto s = decode_axis(image(0xFFFF'FFFF'FFFF'8000ULL), signed_params, kRef, st);
  CHECK(s.periods == -1);
  CHECK(s.fraction == 0x8000);
  CHECK(s.position_sdc == -32768);
  // The same bits in unsigned format are a huge positive count.
  AxisDecodeState st2;
  const auto u = decode_axis(image(0xFFFF'FFFF'FFFF'8000ULL), {}, kRef, st2);
  CHECK(u.periods == 0xFFFF'FFFF'FFFFLL);
}

TEST_CASE("a fraction with any of the low 3 bits set violates the 13-bit format", "[decode]") {
  for (uint64_t low = 1; low < 8; ++low) {
    AxisDecodeState st;
    CHECK_FALSE(decode_axis(image(0xC000 | low), {}, kRef, st).fraction_valid);
  }
  AxisDecodeState st;
  CHECK(decode_axis(image(0xC008), {}, kRef, st).fraction_valid);
}

TEST_CASE("PosTime maps to monotonic time through the NetTime reference", "[decode][nettime]") {
  AxisDecodeState st;
  // Acquired 250 µs before the reference instant.
  const auto s = decode_axis(image(0, 1, 1'000'000 - 250), {}, kRef, st);
  CHECK(s.time_source == TimeSource::NetTime);
  CHECK(s.pos_time_ns == 5'000'000'000 - 250'000);
}

TEST_CASE("PosTime unwraps across the 32-bit NetTime wrap in both directions",
          "[decode][nettime]") {
  // Reference 16 µs after the wrap; stamp 16 µs before it.
  NetTimeRef after_wrap{0x1'0000'0010ULL, 9'000'000'000, true};
  CHECK(net_time_to_monotonic_ns(0xFFFF'FFF0u, after_wrap) == 9'000'000'000 - 32'000);
  // Reference just before the wrap; stamp just after it (a stamp slightly in the future).
  NetTimeRef before_wrap{0x2'FFFF'FFFEULL, 1'000'000'000, true};
  CHECK(net_time_to_monotonic_ns(0x0000'0003u, before_wrap) == 1'000'000'000 + 5'000);
  // Half the range away is still the right side: -2^31 + 1 µs.
  NetTimeRef ref{0x8000'0000ULL, 0, true};
  CHECK(net_time_to_monotonic_ns(1u, ref) == -int64_t{0x7FFF'FFFF} * 1000);
}

TEST_CASE("new_position follows PosCycle changes of fresh samples only", "[decode]") {
  AxisDecodeState st;
  CHECK(decode_axis(image(0, 5), {}, kRef, st).new_position);        // first sample
  CHECK_FALSE(decode_axis(image(0, 5), {}, kRef, st).new_position);  // unchanged
  CHECK(decode_axis(image(0, 6), {}, kRef, st).new_position);
  // A stale cycle (bus kept last values) is never new, even with another PosCycle.
  const auto stale = decode_axis(image(0, 7, 0, false), {}, kRef, st);
  CHECK_FALSE(stale.fresh);
  CHECK_FALSE(stale.new_position);
  CHECK(stale.time_source == TimeSource::None);
  CHECK(decode_axis(image(0, 7), {}, kRef, st).new_position);
  // Wrap of the SINT counter is a change too.
  AxisDecodeState w;
  (void)decode_axis(image(0, 127), {}, kRef, w);
  CHECK(decode_axis(image(0, -128), {}, kRef, w).new_position);
}

TEST_CASE("without PosTime (function model 254) the reception time stamps the sample", "[decode]") {
  AxisDecodeState st;
  AxisDecodeParams p;
  p.has_pos_time = false;
  const auto s = decode_axis(image(0x10000, 1, 12345), p, kRef, st);
  CHECK(s.time_source == TimeSource::RxTimestamp);
  CHECK(s.pos_time_ns == 777);
  CHECK(s.pos_time_raw == 0);
}

TEST_CASE("randomized: decoding inverts the register split for every bit pattern", "[decode]") {
  uint64_t x = 0x9E3779B97F4A7C15ULL;
  for (int i = 0; i < 100000; ++i) {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    AxisDecodeState st;
    AxisDecodeParams p;
    p.signed_format = (i & 1) != 0;
    const auto s = decode_axis(image(x), p, kRef, st);
    const uint64_t rebuilt = (static_cast<uint64_t>(s.periods) << 16) | s.fraction;
    REQUIRE(rebuilt == x);
    REQUIRE(s.fraction_valid == ((x & 7) == 0));
  }
}
