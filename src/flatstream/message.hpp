// Fixed-capacity message storage: what goes into a sender and comes out of a receiver.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <system_error>

#include "flatstream/errors.hpp"
#include "flatstream/protocol.hpp"

namespace ds1928::flatstream {

// One complete message (an EnDat command or reply).
struct Message {
  uint16_t size = 0;
  std::array<uint8_t, kMaxMessageSize> bytes{};

  [[nodiscard]] std::span<const uint8_t> payload() const noexcept { return {bytes.data(), size}; }
};

// What became of a submitted message. Exactly one outcome is produced per accepted submit.
struct SendOutcome {
  uint32_t tag = 0;        // the caller's tag from submit()
  Errc result = Errc::ok;  // ok: delivered (every sequence carrying it acknowledged)

  [[nodiscard]] bool delivered() const noexcept { return result == Errc::ok; }
  [[nodiscard]] std::error_code error() const noexcept { return make_error_code(result); }
};

// Ring buffer with its storage inline. Single-threaded (the engine is driven by one thread).
template <typename T, std::size_t N>
class Ring {
 public:
  [[nodiscard]] std::size_t size() const noexcept { return count_; }
  [[nodiscard]] bool empty() const noexcept { return count_ == 0; }
  [[nodiscard]] bool full() const noexcept { return count_ == N; }
  static constexpr std::size_t capacity() noexcept { return N; }

  // Slot at the back; the caller fills it. Precondition: !full().
  T& push_back() noexcept {
    T& slot = items_[(head_ + count_) % N];
    ++count_;
    return slot;
  }
  // Precondition: !empty().
  void pop_front() noexcept {
    head_ = (head_ + 1) % N;
    --count_;
  }
  // i-th element from the front. Precondition: i < size().
  [[nodiscard]] T& operator[](std::size_t i) noexcept { return items_[(head_ + i) % N]; }
  [[nodiscard]] const T& operator[](std::size_t i) const noexcept {
    return items_[(head_ + i) % N];
  }
  [[nodiscard]] T& front() noexcept { return items_[head_]; }
  void clear() noexcept { head_ = count_ = 0; }

 private:
  std::array<T, N> items_{};
  std::size_t head_ = 0;
  std::size_t count_ = 0;
};

}  // namespace ds1928::flatstream
