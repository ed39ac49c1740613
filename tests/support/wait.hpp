// Waiting for a condition in a test, on a loaded 2-core CI machine or in a sanitizer build:
// poll until the condition holds, give up only after a generous bound. The bound stops a
// failing test from hanging; it is never what the test measures, and the caller asserts the
// returned condition.
#pragma once

#include <chrono>
#include <thread>

namespace ds1928::test {

inline constexpr std::chrono::seconds kWaitBound{60};

template <class Condition>
[[nodiscard]] bool wait_until(Condition&& done, std::chrono::milliseconds bound = kWaitBound) {
  const auto give_up = std::chrono::steady_clock::now() + bound;
  while (!done()) {
    if (std::chrono::steady_clock::now() >= give_up) return done();
    // The poll interval: short against any event awaited, long enough not to steal a core.
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace ds1928::test
