// Helpers of the simulated-module tests: a constant-velocity axis and the module's system tick.
#pragma once

#include <cstdint>

#include "sim/ds1928_module.hpp"

namespace ds1928::sim::test {

inline constexpr int64_t kUs = 1000;

// An axis moving at `periods_per_s` signal periods per second, module cycle 100 µs.
inline SimAxisConfig constant(double periods_per_s) {
  SimAxisConfig c;
  c.profile = MotionProfile::ConstantVelocity;
  c.velocity_periods_per_s = periods_per_s;
  c.module_cycle_us = 100;
  return c;
}

// One system tick of 100 µs (one bus cycle per tick).
inline void step(Ds1928Module& m, int64_t& t) {
  t += 100 * kUs;
  m.tick(t, static_cast<uint64_t>(t / kUs));
}

}  // namespace ds1928::sim::test
