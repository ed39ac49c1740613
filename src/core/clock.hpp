// The project's one clock: CLOCK_MONOTONIC in nanoseconds. Cycle times, reception stamps,
// timeouts and the simulators' NetTime all read it here, so instants taken in different layers
// compare. Both readers go through the vDSO: no system call, safe on the cycle thread.
//
// Code whose time a test drives keeps its seam (a clock callback, a `now` argument, the virtual
// CAN bus' clock) and falls back to now_ns(). The non-RT services' chrono deadlines use
// std::chrono::steady_clock, which on Linux (libstdc++) reads the same CLOCK_MONOTONIC:
// steady_clock::now().time_since_epoch() is now_ns() (core_vocabulary_test checks it).
#pragma once

#include <cstdint>

namespace ds1928::rt {

inline constexpr int64_t kNsPerSec = 1'000'000'000;

// CLOCK_MONOTONIC in ns.
[[nodiscard]] int64_t now_ns() noexcept;

// CLOCK_REALTIME in ns since the Unix epoch: only to relate monotonic instants to wall time
// (kernel receive stamps, capture files, NetTime's SoC), never to measure intervals.
[[nodiscard]] int64_t realtime_ns() noexcept;

// Sleeps until the absolute CLOCK_MONOTONIC instant `deadline_ns` (TIMER_ABSTIME, restarted
// after signals). With spin_ns > 0 it sleeps until deadline − spin_ns and busy-waits on the
// clock for the rest, trading CPU time for the kernel's wake-up latency. Returns the instant
// it observed when it stopped waiting.
int64_t sleep_until(int64_t deadline_ns, int64_t spin_ns = 0) noexcept;

}  // namespace ds1928::rt
