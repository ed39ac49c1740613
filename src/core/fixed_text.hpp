#pragma once

#include <array>
#include <cstddef>
#include <cstdio>
#include <ostream>
#include <string_view>

namespace ds1928 {

// A message built without allocating: text that does not fit is cut at the capacity. Used where a
// refusal is named on the cycle thread (a PDO mapping read from a CN is bound there), which must
// not allocate.
template <std::size_t N>
class FixedText {
 public:
  FixedText& operator<<(std::string_view s) noexcept {
    for (char c : s)
      if (len_ + 1 < N) buf_[len_++] = c;
    buf_[len_] = '\0';
    return *this;
  }
  FixedText& operator<<(unsigned long long v) noexcept {
    std::array<char, 24> digits{};
    const int n = std::snprintf(digits.data(), digits.size(), "%llu", v);
    return *this << std::string_view(digits.data(), n > 0 ? static_cast<std::size_t>(n) : 0);
  }
  FixedText& operator<<(unsigned v) noexcept { return *this << static_cast<unsigned long long>(v); }
  // An object as DS 301 writes it: index in hex, sub-index in decimal ("0x1A00/2").
  FixedText& object(unsigned index, unsigned sub) noexcept {
    std::array<char, 24> text{};
    const int n = std::snprintf(text.data(), text.size(), "0x%04X/%u", index, sub);
    return *this << std::string_view(text.data(), n > 0 ? static_cast<std::size_t>(n) : 0);
  }
  void clear() noexcept {
    len_ = 0;
    buf_[0] = '\0';
  }

  [[nodiscard]] std::string_view view() const noexcept { return {buf_.data(), len_}; }
  operator std::string_view() const noexcept { return view(); }  // NOLINT: reads as text
  [[nodiscard]] bool empty() const noexcept { return len_ == 0; }
  friend bool operator==(const FixedText& a, std::string_view b) noexcept { return a.view() == b; }
  friend std::ostream& operator<<(std::ostream& os, const FixedText& t) { return os << t.view(); }

 private:
  std::array<char, N> buf_{};
  std::size_t len_ = 0;
};

}  // namespace ds1928
