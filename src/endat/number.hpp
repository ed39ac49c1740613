// Numbers typed by a user (ds1928ctl arguments, socket requests): decimal ("169") or hex with a
// 0x/0X prefix ("0xA9"), no sign, no spaces, checked against [min, max].
#pragma once

#include <cstdint>
#include <string_view>

#include "endat/error.hpp"

namespace ds1928::endat {

// Errors: invalid_number (empty, bad digit, "0x" alone, sign, overflow of 64 bits reported as
// number_out_of_range), number_out_of_range.
[[nodiscard]] Result<uint64_t> parse_number(std::string_view text, uint64_t min,
                                            uint64_t max) noexcept;

[[nodiscard]] inline Result<uint8_t> parse_u8(std::string_view text) noexcept {
  auto r = parse_number(text, 0, 0xFF);
  if (!r) return r.error();
  return static_cast<uint8_t>(*r);
}
[[nodiscard]] inline Result<uint16_t> parse_u16(std::string_view text) noexcept {
  auto r = parse_number(text, 0, 0xFFFF);
  if (!r) return r.error();
  return static_cast<uint16_t>(*r);
}

}  // namespace ds1928::endat
