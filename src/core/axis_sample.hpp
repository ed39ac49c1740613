// One axis' decoded state for one cycle, and the pure decoding from the module image.
#pragma once

#include <cstdint>

#include "core/bus.hpp"
#include "x20ds1928/error_bits.hpp"
#include "x20ds1928/module_image.hpp"

namespace ds1928 {

struct AxisSample {
  uint64_t position_raw = 0;   // PositionHW:PositionLW
  int32_t position_sdc = 0;    // low 32 bits read signed ("SDC" view)
  int64_t periods = 0;         // whole sine periods, bits 63..16 (sign-extended in signed format)
  uint16_t fraction = 0;       // fraction of one period, bits 15..0 (13-bit resolution)
  bool fraction_valid = true;  // false when one of the low 3 bits is set in the sin/cos format
  uint32_t pos_time_raw = 0;   // PosTime as sent (NetTime µs, 32 bit)
  int64_t pos_time_ns = 0;     // acquisition instant on CLOCK_MONOTONIC
  TimeSource time_source = TimeSource::None;
  int8_t pos_cycle = 0;
  bool new_position = false;  // PosCycle changed since the previous fresh sample
  uint8_t error_info = 0;
  bool fresh = false;  // inputs arrived this cycle
  // A new position whose NetTime stamp is older than AxisDecodeParams::max_stamp_age_ns before the
  // cycle's reference: the late answer to an earlier cycle's request, taken for this one. Not
  // fresh (published as stale), counted apart.
  bool stamp_too_old = false;
  // The acquisition stalled: more than AxisDecodeParams::stall_limit samples in a row repeated
  // the last position (PosCycle unchanged; with PosTime: PosTime unchanged). Not fresh (stale)
  // until a new position arrives.
  bool stalled = false;
  // A repeat of the last new position (not new): stamped with the cycle in which that position
  // first arrived, so its age grows.
  bool repeated = false;
  // An analogue error holds the last good position (apply_error_policy): published stale.
  bool held = false;
};

// What the decoder remembers between cycles for one axis.
struct AxisDecodeState {
  int8_t last_pos_cycle = 0;
  bool have_last = false;
  uint32_t last_pos_time = 0;  // PosTime of the last new position (NetTime source)
  int64_t first_stamp_ns = 0;  // when the last new position first arrived (RX-stamp source)
  uint32_t repeats = 0;        // fresh samples in a row without a new position
  // The last position published valid: what an analogue error holds (§11.7.6).
  bool have_good = false;
  uint64_t good_position_raw = 0;
};

struct AxisDecodeParams {
  bool signed_format = false;  // EnDatMode bit 1
  // EnDatMode bit 3 clear: the 64 bits are the sin/cos fixed point (48.16, low 3 bits 0,
  // §11.7.1). Set (track off): they are the EnDat position in measuring steps, right-aligned
  // (§11.5.2); `periods`/`fraction` are then its bits 63..16 / 15..0 and every bit pattern is
  // valid. EnDatMode bit 2 (fast clock off) changes the timing only.
  bool sincos_track = true;
  bool has_pos_time = true;  // function model 0 carries PosTime; 254 does not
  // > 0: a new position (PosCycle changed) stamped more than this before the cycle's NetTime
  // reference is not taken as this cycle's (AxisSample::stamp_too_old). A POWERLINK PRes carries
  // no cycle number, so a PRes delayed past the next PReq is indistinguishable from the answer to
  // it; its PosTime tells. A module that stopped acquiring (same PosCycle) is not affected.
  int64_t max_stamp_age_ns = 0;
  // > 0: after this many repeated samples in a row (datasheet §11.5.5: PosCycle counts new
  // positions only — a module whose acquisition stalls resends the same position and PosCycle;
  // under POWERLINK the same PosTime) the sample is stale (AxisSample::stalled) until a new
  // position arrives. 0: off.
  uint32_t stall_limit = 0;
};

// The stamp age beyond which a new position cannot be this cycle's: the module's acquisition lies
// within the previous bus cycle plus one EnDat cycle (at most 1.6 ms, prescaler 8), so twice the
// cycle plus 2 ms leaves room for both and for a late SoC.
[[nodiscard]] constexpr int64_t default_max_stamp_age_ns(int64_t period_ns) noexcept {
  return 2 * period_ns + 2'000'000;
}

// Pure: image + previous state + the bus' NetTime reference → sample. Updates `state`.
[[nodiscard]] AxisSample decode_axis(const AxisIo& io, const AxisDecodeParams& params,
                                     const NetTimeRef& net_time, AxisDecodeState& state) noexcept;

// The error bits' verdict on a decoded sample (x20ds1928/error_bits.hpp, axes[].invalidate_on):
// while a bit whose effect is Hold is set (an analogue error, §11.7.6: "the last correctly
// determined values stay valid") the sample carries the last good position instead of what the
// bus sent and is not fresh (published stale); a fresh sample without an invalidating or holding
// bit becomes the new last good position. Returns the assessment. Pure, allocation-free.
ErrorAssessment apply_error_policy(AxisSample& sample, const ErrorPolicy& policy,
                                   const ErrorWords& words, const AxisDecodeParams& params,
                                   AxisDecodeState& state) noexcept;

// Maps a 32-bit NetTime stamp (µs) to CLOCK_MONOTONIC ns through `ref`, correct across the
// 32-bit wrap for stamps within ±2^31 µs (35 min 47 s) of the reference.
[[nodiscard]] constexpr int64_t net_time_to_monotonic_ns(uint32_t stamp_us,
                                                         const NetTimeRef& ref) noexcept {
  const auto offset_us = static_cast<int32_t>(stamp_us - static_cast<uint32_t>(ref.net_time_us));
  return ref.monotonic_ns + static_cast<int64_t>(offset_us) * 1000;
}

}  // namespace ds1928
