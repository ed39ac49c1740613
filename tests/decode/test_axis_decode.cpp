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

TEST_CASE("a new position stamped too long before its cycle is a late answer: stale, not news",
          "[decode][nettime]") {
  // 1 ms cycle: the bound is 2 cycles + 2 ms = 4 ms before the reference (SoC at 1'000'000 µs).
  AxisDecodeParams p;
  p.max_stamp_age_ns = default_max_stamp_age_ns(1'000'000);
  REQUIRE(p.max_stamp_age_ns == 4'000'000);
  AxisDecodeState st;
  // An on-time sample: PosCycle 5, stamped 300 µs before the SoC.
  auto s = decode_axis(image(0x10000, 5, 999'700), p, kRef, st);
  CHECK(s.fresh);
  CHECK(s.new_position);
  CHECK_FALSE(s.stamp_too_old);
  // The late answer to an earlier request: an older PosCycle, stamped 12 ms before this SoC.
  s = decode_axis(image(0x0F000, 4, 988'000), p, kRef, st);
  CHECK_FALSE(s.fresh);
  CHECK_FALSE(s.new_position);
  CHECK(s.stamp_too_old);
  CHECK(s.pos_time_ns == 5'000'000'000 - 12'000'000);
  // Exactly at the bound is still this cycle's; 1 µs beyond is not.
  AxisDecodeState edge;
  CHECK(decode_axis(image(0x10000, 6, 996'000), p, kRef, edge).fresh);
  AxisDecodeState beyond;
  CHECK(decode_axis(image(0x10000, 6, 995'999), p, kRef, beyond).stamp_too_old);
  // The decoder kept PosCycle 5 across the late one: the next on-time PosCycle 6 is new.
  s = decode_axis(image(0x11000, 6, 1'000'000), p, kRef, st);
  CHECK(s.fresh);
  CHECK(s.new_position);
  // A module that stopped acquiring repeats PosCycle and stamp: old, but not a late answer; the
  // sample stays fresh (its ErrorInfo, not the bus, says what is wrong).
  for (int k = 0; k < 3; ++k) {
    s = decode_axis(image(0x11000, 6, 1'000'000), p, NetTimeRef{1'050'000, 5'050'000'000, true},
                    st);
    CHECK(s.fresh);
    CHECK_FALSE(s.new_position);
    CHECK_FALSE(s.stamp_too_old);
  }
  // Without a bound (0) or without NetTime nothing is judged by age.
  AxisDecodeState none;
  CHECK(decode_axis(image(0x10000, 7, 900'000), {}, kRef, none).fresh);
  AxisDecodeState invalid_ref;
  CHECK(decode_axis(image(0x10000, 7, 900'000), p, NetTimeRef{}, invalid_ref).fresh);
}

TEST_CASE("error bits: a warning keeps the position, an analogue error holds the last good one",
          "[decode][errors]") {
  AxisDecodeState st;
  const AxisDecodeParams params;
  const ErrorPolicy policy = error_policy();
  auto step = [&](uint64_t raw, int8_t cycle, ErrorWords w) {
    AxisSample s = decode_axis(image(raw, cycle), params, {}, st);
    const ErrorAssessment a = apply_error_policy(s, policy, w, params, st);
    return std::pair{s, a};
  };
  auto [s0, a0] = step(0x0000'0000'0005'8000, 1, {});
  CHECK(s0.fresh);
  CHECK_FALSE(s0.held);
  // EnDatRefWarning: flagged, the position is this cycle's and fresh.
  auto [s1, a1] = step(0x0000'0000'0006'0000, 2, {error_info::kEnDatRefWarning, 0, 0});
  CHECK(s1.fresh);
  CHECK(s1.position_raw == 0x0000'0000'0006'0000ULL);
  CHECK(a1.warning);
  CHECK_FALSE(a1.invalidate);
  // VssCheckError: the bus sends another value, the sample carries the last good one, not fresh.
  auto [s2, a2] = step(0x0000'0000'0123'0000, 3, {error_info::kVssCheckError, 0, 0});
  CHECK(a2.hold);
  CHECK(s2.held);
  CHECK_FALSE(s2.fresh);
  CHECK_FALSE(s2.new_position);
  CHECK(s2.position_raw == 0x0000'0000'0006'0000ULL);
  CHECK(s2.periods == 6);
  CHECK(s2.fraction == 0);
  // Cleared: the new position counts again.
  auto [s3, a3] = step(0x0000'0000'0007'0000, 4, {});
  CHECK(s3.fresh);
  CHECK_FALSE(s3.held);
  CHECK(s3.position_raw == 0x0000'0000'0007'0000ULL);
  // A fault invalidates but does not become the last good position.
  auto [s4, a4] = step(0x0000'0000'0999'0000, 5, {error_info::kEnDatComError, 0, 0});
  CHECK(a4.invalidate);
  auto [s5, a5] = step(0x0000'0000'0888'0000, 6, {error_info::kVssCheckError, 0, 0});
  CHECK(s5.position_raw == 0x0000'0000'0007'0000ULL);
}

TEST_CASE("position formats follow EnDatMode: sin/cos 48.16, or the EnDat position in steps",
          "[decode][format]") {
  // Low 3 bits set: a format violation in 48.16, an ordinary step count with the track off.
  const uint64_t raw = 0x0000'0012'3456'789FULL;
  AxisDecodeParams sincos;
  AxisDecodeParams steps;
  steps.sincos_track = false;
  for (const bool is_signed : {false, true}) {
    sincos.signed_format = steps.signed_format = is_signed;
    AxisDecodeState a, b;
    const auto s = decode_axis(image(raw), sincos, kRef, a);
    CHECK_FALSE(s.fraction_valid);
    const auto e = decode_axis(image(raw), steps, kRef, b);
    CHECK(e.fraction_valid);
    CHECK(e.position_raw == raw);
    // periods:fraction are the bits 63..16:15..0 in both formats (readers rebuild the 64 bits).
    CHECK(e.periods == 0x12'3456);
    CHECK(e.fraction == 0x789F);
  }
  // Signed, track off: the module sign-extends the encoder's position; read back negative.
  AxisDecodeState c;
  steps.signed_format = true;
  const auto n = decode_axis(image(static_cast<uint64_t>(int64_t{-5})), steps, kRef, c);
  CHECK(n.fraction_valid);
  CHECK(static_cast<int64_t>(n.position_raw) == -5);
  CHECK(n.periods * 65536 + n.fraction == -5);
}
