// The daemon caps the default thread stack so that mlockall does not lock 8 MiB per thread.
// Its own program: the default it sets holds for every thread the process starts afterwards.
#include <pthread.h>

#include <catch2/catch.hpp>
#include <thread>

#include "core/rt_setup.hpp"

using namespace ds1928;

namespace {
struct NewThreadStack {
  std::size_t size = 0;  // the whole block, TLS included
  std::size_t left = 0;  // below the thread's first frame: what its code can use
};

NewThreadStack stack_of_new_thread() {
  NewThreadStack stack;
  std::thread([&] {
    pthread_attr_t attr;
    REQUIRE(pthread_getattr_np(pthread_self(), &attr) == 0);
    REQUIRE(pthread_attr_getstacksize(&attr, &stack.size) == 0);
    pthread_attr_destroy(&attr);
    stack.left = rt::stack_left();
  }).join();
  return stack;
}

constexpr std::size_t kMiB = 1024 * 1024;
}  // namespace

TEST_CASE("the default thread stack is capped, never raised", "[core][rt]") {
  const NewThreadStack before = stack_of_new_thread();
  INFO("default stack of a new thread before: " << before.size);
  REQUIRE(before.size > 2 * kMiB);  // glibc follows RLIMIT_STACK (8 MiB here)

  const std::size_t overhead = rt::thread_stack_overhead();
  INFO("TLS and descriptor at the top of each stack: " << overhead);
  REQUIRE(overhead > 0);
  REQUIRE(overhead < kMiB);

  REQUIRE(rt::limit_default_thread_stack(kMiB).ok());
  const NewThreadStack capped = stack_of_new_thread();
  INFO("capped stack: " << capped.size << ", usable " << capped.left);
  // The cap is on the usable stack: 1 MiB below the thread's first frame, within a page or two.
  CHECK(capped.left >= kMiB - 8192);
  CHECK(capped.size < before.size);
  CHECK(capped.size <= kMiB + overhead + 4096);

  // Asking for more than the current default leaves it as it is.
  REQUIRE(rt::limit_default_thread_stack(4 * kMiB).ok());
  CHECK(stack_of_new_thread().size == capped.size);

  // A thread still deep enough for the cycle thread's pre-faulted stack.
  std::size_t touched = 0;
  std::thread([&] { touched = rt::prefault_stack(256 * 1024); }).join();
  CHECK(touched == 256 * 1024);
}

TEST_CASE("a thread with a small stack pre-faults what it has, not past its guard page",
          "[core][rt]") {
  // 128 KiB of usable stack: less than the 256 KiB asked plus the reserve. Before prefault_stack
  // looked at the stack it had, this was a SIGSEGV (TSan's TLS left a 1 MiB thread 250 KiB).
  pthread_attr_t attr;
  REQUIRE(pthread_attr_init(&attr) == 0);
  REQUIRE(pthread_attr_setstacksize(&attr, 128 * 1024 + rt::thread_stack_overhead()) == 0);
  struct Result {
    std::size_t left = 0;
    std::size_t touched = 0;
  } result;
  pthread_t thread;
  REQUIRE(pthread_create(
              &thread, &attr,
              [](void* out) -> void* {
                auto* r = static_cast<Result*>(out);
                r->left = rt::stack_left();
                r->touched = rt::prefault_stack(256 * 1024);
                return nullptr;
              },
              &result) == 0);
  pthread_join(thread, nullptr);
  pthread_attr_destroy(&attr);
  INFO("stack left " << result.left << ", touched " << result.touched);
  CHECK(result.touched + rt::kStackReserve <= result.left);
  // TSan's pthread_create raises any stack below its TLS + 128 KiB, so there the thread may have
  // room for all 256 KiB.
  if (result.left < 256 * 1024 + rt::kStackReserve) {
    CHECK(result.touched > 0);
    CHECK(result.touched < 256 * 1024);
  } else {
    CHECK(result.touched == 256 * 1024);
  }
}
