#include "endat/number.hpp"

namespace ds1928::endat {

Result<uint64_t> parse_number(std::string_view text, uint64_t min, uint64_t max) noexcept {
  unsigned base = 10;
  if (text.size() >= 2 && text[0] == '0' && (text[1] == 'x' || text[1] == 'X')) {
    base = 16;
    text.remove_prefix(2);
  }
  if (text.empty()) return Errc::invalid_number;
  uint64_t value = 0;
  bool overflow = false;
  for (char c : text) {
    unsigned digit = 0;
    if (c >= '0' && c <= '9') {
      digit = static_cast<unsigned>(c - '0');
    } else if (base == 16 && c >= 'a' && c <= 'f') {
      digit = static_cast<unsigned>(c - 'a' + 10);
    } else if (base == 16 && c >= 'A' && c <= 'F') {
      digit = static_cast<unsigned>(c - 'A' + 10);
    } else {
      return Errc::invalid_number;
    }
    if (value > (UINT64_MAX - digit) / base) overflow = true;  // keep scanning for bad digits
    value = value * base + digit;
  }
  if (overflow || value < min || value > max) return Errc::number_out_of_range;
  return value;
}

}  // namespace ds1928::endat
