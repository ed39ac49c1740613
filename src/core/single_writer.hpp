// Counters with one writer (the cycle thread, a node thread, a capture point's producer) that
// other threads read: the writer adds with a relaxed load and store instead of an atomic
// read-modify-write, which x86 makes a locked instruction the cycle does not need when no second
// thread writes. A counter with two writers (a CAN port's sending and receiving threads) uses
// fetch_add instead.
#pragma once

#include <atomic>

namespace ds1928 {

template <class T>
inline void single_writer_add(std::atomic<T>& counter, T n = 1) noexcept {
  counter.store(counter.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

}  // namespace ds1928
