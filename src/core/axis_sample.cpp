#include "core/axis_sample.hpp"

namespace ds1928 {
namespace {

void set_position(AxisSample& s, uint64_t raw, const AxisDecodeParams& params) noexcept {
  s.position_raw = raw;
  s.position_sdc = static_cast<int32_t>(static_cast<uint32_t>(raw));
  s.periods =
      params.signed_format ? (static_cast<int64_t>(raw) >> 16) : static_cast<int64_t>(raw >> 16);
  s.fraction = static_cast<uint16_t>(raw & 0xFFFF);
  s.fraction_valid = !params.sincos_track || (raw & 0x7) == 0;
}

}  // namespace

AxisSample decode_axis(const AxisIo& io, const AxisDecodeParams& params, const NetTimeRef& net_time,
                       AxisDecodeState& state) noexcept {
  AxisSample s;
  s.fresh = io.inputs_fresh;
  const ModuleInputs& in = io.inputs;
  set_position(s, (static_cast<uint64_t>(in.position_hw) << 32) | in.position_lw, params);
  s.pos_cycle = in.pos_cycle;
  s.error_info = in.error_info;
  if (!io.inputs_fresh) {
    // Last valid values are kept on the bus; they are not a new position.
    return s;
  }
  if (params.has_pos_time && net_time.valid) {
    s.pos_time_raw = in.pos_time_us;
    s.pos_time_ns = net_time_to_monotonic_ns(in.pos_time_us, net_time);
    s.time_source = TimeSource::NetTime;
  } else {
    s.pos_time_raw = 0;
    s.pos_time_ns = io.rx_time_ns;
    s.time_source = TimeSource::RxTimestamp;
  }
  s.new_position = !state.have_last || state.last_pos_cycle != in.pos_cycle;
  if (s.time_source == TimeSource::NetTime && state.have_last && !s.new_position &&
      in.pos_time_us != state.last_pos_time) {
    // PosCycle wrapped onto the same value, or the module stamps a new acquisition: PosTime moved.
    s.new_position = true;
  }
  if (!s.new_position && state.have_last) {
    // A repeat of the last position: never new, stamped when it first arrived (with NetTime its
    // PosTime is that stamp already), stale once the repeats exceed the limit.
    s.repeated = true;
    if (s.time_source == TimeSource::RxTimestamp) s.pos_time_ns = state.first_stamp_ns;
    ++state.repeats;
    if (params.stall_limit > 0 && state.repeats > params.stall_limit) {
      s.fresh = false;
      s.stalled = true;
    }
    return s;
  }
  if (s.new_position && s.time_source == TimeSource::NetTime && params.max_stamp_age_ns > 0 &&
      net_time.monotonic_ns - s.pos_time_ns > params.max_stamp_age_ns) {
    // Not this cycle's position: the decoder keeps its PosCycle, so the next on-time sample
    // counts as new again.
    s.fresh = false;
    s.new_position = false;
    s.stamp_too_old = true;
    return s;
  }
  state.last_pos_cycle = in.pos_cycle;
  state.last_pos_time = in.pos_time_us;
  state.first_stamp_ns = s.pos_time_ns;
  state.repeats = 0;
  state.have_last = true;
  return s;
}

ErrorAssessment apply_error_policy(AxisSample& sample, const ErrorPolicy& policy,
                                   const ErrorWords& words, const AxisDecodeParams& params,
                                   AxisDecodeState& state) noexcept {
  const ErrorAssessment a = assess(policy, words);
  if (a.hold) {
    sample.held = true;
    sample.fresh = false;
    sample.new_position = false;
    if (state.have_good) set_position(sample, state.good_position_raw, params);
    return a;
  }
  if (sample.fresh && !a.invalidate && sample.fraction_valid) {
    state.have_good = true;
    state.good_position_raw = sample.position_raw;
  }
  return a;
}

}  // namespace ds1928
