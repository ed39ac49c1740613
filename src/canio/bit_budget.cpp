#include "canio/bit_budget.hpp"

namespace ds1928::canio {
namespace {

int64_t bits_to_ns(uint64_t bits, uint32_t bitrate) noexcept {
  if (bitrate == 0) return 0;
  // Rounded up: a budget must never look shorter than the bus needs.
  return static_cast<int64_t>((bits * 1'000'000'000ull + bitrate - 1) / bitrate);
}

}  // namespace

CycleBudget cycle_budget(const CycleLoad& load) noexcept {
  CycleBudget b;
  const FrameBits in = frame_bits(load.input_bytes, load.extended_ids);
  const FrameBits out = frame_bits(load.output_bytes, load.extended_ids);
  const uint64_t n_in = uint64_t{load.modules} * load.input_frames_per_module;
  const uint64_t n_out = uint64_t{load.modules} * load.output_frames_per_module;
  b.frames = static_cast<uint32_t>(n_in + n_out);
  b.bits_nominal = n_in * in.nominal + n_out * out.nominal;
  b.bits_worst_case = n_in * in.worst_case + n_out * out.worst_case;
  if (load.sync) {
    // SYNC uses a standard identifier (0x080) whatever the objects use.
    const FrameBits s = frame_bits(load.sync_bytes, false);
    ++b.frames;
    b.bits_nominal += s.nominal;
    b.bits_worst_case += s.worst_case;
  }
  b.time_nominal_ns = bits_to_ns(b.bits_nominal, load.bitrate);
  b.time_worst_case_ns = bits_to_ns(b.bits_worst_case, load.bitrate);
  return b;
}

CycleFit check_cycle(const CycleLoad& load, int64_t period_ns) noexcept {
  CycleFit f;
  f.budget = cycle_budget(load);
  f.fits = period_ns > 0 && f.budget.time_worst_case_ns <= period_ns;
  f.fits_nominal = period_ns > 0 && f.budget.time_nominal_ns <= period_ns;
  f.margin_ns = period_ns - f.budget.time_worst_case_ns;
  if (period_ns > 0) {
    f.load_worst_case =
        static_cast<double>(f.budget.time_worst_case_ns) / static_cast<double>(period_ns);
    f.load_nominal = static_cast<double>(f.budget.time_nominal_ns) / static_cast<double>(period_ns);
  }
  return f;
}

}  // namespace ds1928::canio
