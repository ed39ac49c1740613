// One writer hands the latest value of a large struct to one reader, neither ever waiting for
// the other: three buffers, the writer fills its own and swaps it into the middle, the reader
// swaps the middle out when it holds something new. No lock, no allocation, no torn value.
// Used where the cycle thread publishes a status snapshot every cycle for the normal thread.
#pragma once

#include <array>
#include <atomic>
#include <functional>

namespace ds1928 {

template <class T>
class TripleBuffer {
 public:
  TripleBuffer() = default;
  // Every buffer starts as `init` (e.g. vectors sized once, before the cycle thread starts).
  explicit TripleBuffer(const T& init) : buffers_{init, init, init} {}

  // Writer side: the buffer to fill completely, then publish() it.
  [[nodiscard]] T& back() noexcept { return buffers_[back_]; }
  void publish() noexcept {
    back_ = middle_.exchange(back_ | kFresh, std::memory_order_acq_rel) & kIndex;
  }

  // Reader side (one thread at a time): the latest published value, or the one read before when
  // nothing was published since. The reference stays valid until the next read().
  [[nodiscard]] const T& read() noexcept {
    if ((middle_.load(std::memory_order_acquire) & kFresh) != 0)
      front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return buffers_[front_];
  }

  // Before the threads start or after they stopped: change every buffer alike.
  void for_each(const std::function<void(T&)>& f) {
    for (T& b : buffers_) f(b);
  }

 private:
  static constexpr unsigned kIndex = 3u;
  static constexpr unsigned kFresh = 4u;
  std::array<T, 3> buffers_{};
  unsigned back_ = 0;   // writer's
  unsigned front_ = 1;  // reader's
  std::atomic<unsigned> middle_{2};
};

}  // namespace ds1928
