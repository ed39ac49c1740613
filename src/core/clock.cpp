#include "core/clock.hpp"

#include <cerrno>
#include <ctime>

namespace ds1928::rt {
namespace {

[[nodiscard]] int64_t read(clockid_t id) noexcept {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<int64_t>(ts.tv_sec) * kNsPerSec + ts.tv_nsec;
}

[[nodiscard]] timespec to_timespec(int64_t ns) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / kNsPerSec);
  ts.tv_nsec = static_cast<long>(ns % kNsPerSec);
  return ts;
}

}  // namespace

int64_t now_ns() noexcept {
  return read(CLOCK_MONOTONIC);
}

int64_t realtime_ns() noexcept {
  return read(CLOCK_REALTIME);
}

int64_t sleep_until(int64_t deadline_ns, int64_t spin_ns) noexcept {
  const int64_t wake_ns = spin_ns > 0 ? deadline_ns - spin_ns : deadline_ns;
  const timespec ts = to_timespec(wake_ns);
  // EINTR: a signal handler ran; the deadline is absolute, so just go back to sleep.
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
  int64_t now = now_ns();
  while (now < deadline_ns) now = now_ns();
  return now;
}

}  // namespace ds1928::rt
