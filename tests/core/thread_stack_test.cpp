// The daemon caps the default thread stack so that mlockall does not lock 8 MiB per thread.
// Its own program: the default it sets holds for every thread the process starts afterwards.
#include <pthread.h>

#include <catch2/catch.hpp>
#include <thread>

#include "core/rt_setup.hpp"

using namespace ds1928;

namespace {
std::size_t stack_of_new_thread() {
  std::size_t size = 0;
  std::thread([&] {
    pthread_attr_t attr;
    REQUIRE(pthread_getattr_np(pthread_self(), &attr) == 0);
    REQUIRE(pthread_attr_getstacksize(&attr, &size) == 0);
    pthread_attr_destroy(&attr);
  }).join();
  return size;
}
}  // namespace

TEST_CASE("the default thread stack is capped, never raised", "[core][rt]") {
  const std::size_t before = stack_of_new_thread();
  INFO("default stack of a new thread before: " << before);
  REQUIRE(before > 1024 * 1024);  // glibc follows RLIMIT_STACK (8 MiB here)

  REQUIRE(rt::limit_default_thread_stack(1024 * 1024).ok());
  CHECK(stack_of_new_thread() == 1024 * 1024);

  // Asking for more than the current default leaves it as it is.
  REQUIRE(rt::limit_default_thread_stack(4 * 1024 * 1024).ok());
  CHECK(stack_of_new_thread() == 1024 * 1024);

  // A thread still deep enough for the cycle thread's pre-faulted stack.
  std::thread([] { rt::prefault_stack(256 * 1024); }).join();
}
