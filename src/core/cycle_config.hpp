// What the cycle engine is told: the period and how it may use the CPU (docs/realtime.md).
// The configuration (`cycle:`) fills it; the engine checks it again (CycleEngine::validate).
#pragma once

#include <cstdint>

namespace ds1928 {

// What the cycle starts are aligned to: the daemon's own start (monotonic), or multiples of
// the period in CLOCK_TAI, so that daemons of one PTP domain cycle in phase (docs/realtime.md).
enum class TimebaseKind : uint8_t { Monotonic = 0, Tai = 1 };

struct CycleConfig {
  uint32_t period_us = 1000;
  int rt_priority = 80;  // SCHED_FIFO 1..99
  int cpu = -1;          // -1 = no affinity
  uint32_t spin_us = 0;  // busy-wait this long before the deadline (0 = off)
  bool hold_cpu_dma_latency = true;
  bool lock_memory = true;
  TimebaseKind timebase = TimebaseKind::Monotonic;
};

}  // namespace ds1928
