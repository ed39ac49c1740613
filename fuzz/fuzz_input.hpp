// Reading a fuzz input as a stream of fields: each take returns what is left (zeros past the
// end), so every input, however short, drives the code under test to its end.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>

namespace ds1928::fuzz {

class Input {
 public:
  Input(const uint8_t* data, std::size_t size) noexcept : data_(data, size) {}

  [[nodiscard]] bool empty() const noexcept { return pos_ >= data_.size(); }
  [[nodiscard]] uint8_t u8() noexcept { return empty() ? 0 : data_[pos_++]; }
  [[nodiscard]] uint16_t u16() noexcept { return static_cast<uint16_t>(u8() | (u8() << 8)); }
  // Up to `n` bytes (fewer at the end of the input).
  [[nodiscard]] std::span<const uint8_t> bytes(std::size_t n) noexcept {
    const std::size_t k = std::min(n, data_.size() - std::min(pos_, data_.size()));
    auto out = data_.subspan(std::min(pos_, data_.size()), k);
    pos_ += k;
    return out;
  }
  [[nodiscard]] std::span<const uint8_t> rest() noexcept { return bytes(data_.size()); }

 private:
  std::span<const uint8_t> data_;
  std::size_t pos_ = 0;
};

}  // namespace ds1928::fuzz
