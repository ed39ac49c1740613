// The cycle engine's timeline aligned to CLOCK_TAI (cycle.timebase: tai): cycle starts fall on
// whole multiples of the period in TAI, so that daemons whose TAI clocks agree (linuxptp's
// phc2sys disciplines them from one PTP grandmaster) cycle in phase. The engine sleeps on
// CLOCK_MONOTONIC as always; this class keeps the monotonic timeline (t0) that maps onto the
// TAI grid through the measured offset TAI − MONOTONIC.
//
// The two clocks share their frequency (adjtimex slews both), so the offset moves only when the
// TAI clock is stepped. A change beyond kStepThresholdNs seen on two measurements in a row is a
// step: the timeline is re-anchored once, by the step reduced modulo the period (at most half a
// period either way, the cycle index continues), and counted; smaller changes are measurement
// noise and leave the timeline alone. Pure: the engine feeds it clock readings, tests a fake
// clock.
#pragma once

#include <cstdint>

namespace ds1928 {

class TaiTimeline {
 public:
  static constexpr int64_t kStepThresholdNs = 5'000;

  explicit TaiTimeline(int64_t period_ns) noexcept : period_(period_ns) {}

  // The timeline's t0 (CLOCK_MONOTONIC): cycle 0 is the first TAI multiple of the period at
  // least one period after `mono_now`.
  int64_t anchor(int64_t mono_now, int64_t tai_offset) noexcept;

  // Once per cycle with a fresh measurement of TAI − MONOTONIC. Returns how far the cycle starts
  // moved (0 almost always; a re-anchor's shift after a confirmed step).
  int64_t follow(int64_t tai_offset) noexcept;

  [[nodiscard]] int64_t t0() const noexcept { return t0_; }
  [[nodiscard]] int64_t tai_offset() const noexcept { return offset_; }
  [[nodiscard]] uint32_t steps() const noexcept { return steps_; }
  [[nodiscard]] int64_t last_step_ns() const noexcept { return last_step_; }

 private:
  int64_t period_;
  int64_t t0_ = 0;
  int64_t offset_ = 0;
  int64_t pending_ = 0;  // a changed offset seen once, awaiting confirmation
  bool has_pending_ = false;
  uint32_t steps_ = 0;
  int64_t last_step_ = 0;
};

// TAI − MONOTONIC, read between two monotonic readings: the pair whose readings lie closest
// together out of a few (a preempted reading is discarded). Through the vDSO: no system call.
[[nodiscard]] int64_t measure_tai_offset() noexcept;

}  // namespace ds1928
