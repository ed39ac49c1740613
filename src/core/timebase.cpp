#include "core/timebase.hpp"

#include <ctime>

#include "core/clock.hpp"

namespace ds1928 {
namespace {

int64_t floor_div(int64_t a, int64_t b) noexcept {
  const int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

// `shift` reduced to [−period/2, period/2): only the phase on the grid matters.
int64_t phase_of(int64_t shift, int64_t period) noexcept {
  int64_t r = shift - floor_div(shift, period) * period;  // [0, period)
  if (r >= period / 2) r -= period;
  return r;
}

int64_t abs64(int64_t v) noexcept {
  return v < 0 ? -v : v;
}

}  // namespace

int64_t TaiTimeline::anchor(int64_t mono_now, int64_t tai_offset) noexcept {
  offset_ = tai_offset;
  has_pending_ = false;
  const int64_t tai_first = mono_now + period_ + tai_offset;
  const int64_t k = floor_div(tai_first + period_ - 1, period_);  // ceil
  t0_ = k * period_ - tai_offset;
  return t0_;
}

int64_t TaiTimeline::follow(int64_t tai_offset) noexcept {
  const int64_t change = tai_offset - offset_;
  if (abs64(change) < kStepThresholdNs) {
    has_pending_ = false;
    return 0;
  }
  // Confirmed by a second measurement near the first: a step, not one disturbed reading.
  if (!has_pending_ || abs64(tai_offset - pending_) >= kStepThresholdNs) {
    pending_ = tai_offset;
    has_pending_ = true;
    return 0;
  }
  has_pending_ = false;
  // TAI moved by `change` against MONOTONIC: the TAI grid's monotonic instants move by −change.
  const int64_t shift = phase_of(-change, period_);
  offset_ = tai_offset;
  t0_ += shift;
  ++steps_;
  last_step_ = shift;
  return shift;
}

int64_t measure_tai_offset() noexcept {
  int64_t best_gap = INT64_MAX;
  int64_t best = 0;
  for (int i = 0; i < 3; ++i) {
    timespec a{}, t{}, b{};
    clock_gettime(CLOCK_MONOTONIC, &a);
    clock_gettime(CLOCK_TAI, &t);
    clock_gettime(CLOCK_MONOTONIC, &b);
    const int64_t ma = int64_t{a.tv_sec} * rt::kNsPerSec + a.tv_nsec;
    const int64_t mb = int64_t{b.tv_sec} * rt::kNsPerSec + b.tv_nsec;
    const int64_t tai = int64_t{t.tv_sec} * rt::kNsPerSec + t.tv_nsec;
    if (mb - ma < best_gap) {
      best_gap = mb - ma;
      best = tai - ma - (mb - ma) / 2;
    }
  }
  return best;
}

}  // namespace ds1928
