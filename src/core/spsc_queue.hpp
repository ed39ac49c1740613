// Bounded single-producer / single-consumer queue: the only way data crosses between the
// cycle thread and the normal-priority thread. Storage is inside the object (no heap), push
// and pop never block and never call into the kernel.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <optional>
#include <type_traits>

namespace ds1928 {

template <typename T, std::size_t Capacity>
class SpscQueue {
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0,
                "Capacity must be a power of two");
  static_assert(std::is_nothrow_copy_assignable_v<T> || std::is_nothrow_move_assignable_v<T>);

 public:
  // Producer side. False when full: the caller decides (count, retry next cycle), nothing is lost
  // silently.
  [[nodiscard]] bool try_push(const T& value) noexcept {
    const auto head = head_.load(std::memory_order_relaxed);
    if (head - tail_cached_ == Capacity) {
      tail_cached_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cached_ == Capacity) return false;
    }
    slots_[head & (Capacity - 1)] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer side.
  [[nodiscard]] std::optional<T> try_pop() noexcept {
    const auto tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cached_) {
      head_cached_ = head_.load(std::memory_order_acquire);
      if (tail == head_cached_) return std::nullopt;
    }
    std::optional<T> out{std::move(slots_[tail & (Capacity - 1)])};
    tail_.store(tail + 1, std::memory_order_release);
    return out;
  }

  // Consumer side: the oldest element without taking it (nullptr when empty), so a consumer that
  // cannot serve it yet leaves it queued; drop_front() then takes it.
  [[nodiscard]] T* front() noexcept {
    const auto tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cached_) {
      head_cached_ = head_.load(std::memory_order_acquire);
      if (tail == head_cached_) return nullptr;
    }
    return &slots_[tail & (Capacity - 1)];
  }
  void drop_front() noexcept {
    tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release);
  }

  // Producer side: true when the next try_push would fail.
  [[nodiscard]] bool full() const noexcept {
    return head_.load(std::memory_order_relaxed) - tail_.load(std::memory_order_acquire) ==
           Capacity;
  }
  [[nodiscard]] bool empty() const noexcept {
    return head_.load(std::memory_order_acquire) == tail_.load(std::memory_order_acquire);
  }
  static constexpr std::size_t capacity() noexcept { return Capacity; }

 private:
  alignas(64) std::atomic<std::size_t> head_{0};
  std::size_t tail_cached_ = 0;  // producer's view of tail_
  alignas(64) std::atomic<std::size_t> tail_{0};
  std::size_t head_cached_ = 0;  // consumer's view of head_
  alignas(64) std::array<T, Capacity> slots_{};
};

}  // namespace ds1928
