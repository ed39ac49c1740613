// Counts heap allocations and mutex locks made by one thread, for tests that prove a code path
// (the cycle thread's) allocates nothing and takes no mutex.
//
// Linking ds1928_test_support into a test program replaces, for that whole program, the global
// operator new/delete (all forms), the malloc family (malloc, calloc, realloc, reallocarray,
// free, memalign, aligned_alloc, posix_memalign, valloc, pvalloc) and pthread_mutex_lock /
// pthread_mutex_trylock with versions that forward to glibc and, when counting is switched on
// for the calling thread, count the call. Calls from other threads are never counted, so a test
// can switch counting on inside the cycle thread while its main thread does what it likes.
//
// Under ASan and TSan the sanitizer's allocator cannot be replaced: its malloc/free hooks count
// instead, and operator new is counted as malloc (counts_new_separately() is false). Their
// runtimes also intercept the mutex entry points (TSan pthread_mutex_lock, ASan glibc's
// __pthread_mutex_lock), so mutex locks are not counted there (counts_mutexes() is false): tests
// then skip that one check and say so; the normal build makes it.
//
// Counting only sees calls that reach these symbols: glibc-internal locks (lll_lock) and
// direct futex system calls are not mutex locks in this sense.
#pragma once

#include <cstddef>
#include <cstdint>

namespace ds1928::test {

struct HeapCounts {
  uint64_t new_calls = 0;      // operator new / new[] (any form)
  uint64_t delete_calls = 0;   // operator delete / delete[] of a non-null pointer
  uint64_t malloc_calls = 0;   // malloc family, including realloc and calloc
  uint64_t free_calls = 0;     // free of a non-null pointer
  uint64_t mutex_locks = 0;    // pthread_mutex_lock + pthread_mutex_trylock
  std::size_t first_size = 0;  // size of the first counted allocation (a hint for debugging)

  [[nodiscard]] uint64_t allocations() const noexcept { return new_calls + malloc_calls; }
  [[nodiscard]] uint64_t deallocations() const noexcept { return delete_calls + free_calls; }
};

// Zeroes the calling thread's counts and starts counting on it.
void begin_counting() noexcept;
// Stops counting on the calling thread and returns what was counted since begin_counting().
HeapCounts end_counting() noexcept;
// What has been counted on the calling thread so far; counting stays as it is.
[[nodiscard]] HeapCounts current_counts() noexcept;
[[nodiscard]] bool counting() noexcept;
// What this build can tell apart (see above).
[[nodiscard]] bool counts_new_separately() noexcept;
[[nodiscard]] bool counts_mutexes() noexcept;

// begin_counting() for the lifetime of a scope, then end_counting() (its result in counts()).
class ScopedCounting {
 public:
  ScopedCounting() noexcept { begin_counting(); }
  ~ScopedCounting() { (void)stop(); }
  ScopedCounting(const ScopedCounting&) = delete;
  ScopedCounting& operator=(const ScopedCounting&) = delete;

  // Stops early and returns the counts; later calls return the same counts.
  HeapCounts stop() noexcept {
    if (active_) {
      counts_ = end_counting();
      active_ = false;
    }
    return counts_;
  }
  [[nodiscard]] HeapCounts counts() const noexcept { return active_ ? current_counts() : counts_; }

 private:
  HeapCounts counts_{};
  bool active_ = true;
};

}  // namespace ds1928::test
