// Human-readable names for EnDat status words, memory areas
// (MRS codes) and temperature words. For status output and ds1928ctl; not for the cycle thread.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace ds1928::endat {

// Names of the set bits of the EnDatError / EnDatWarning words (x20ds1928/error_bits.hpp); a set
// reserved bit appears as "<register> reserved bit N".
[[nodiscard]] std::vector<std::string> endat_error_names(uint16_t word);
[[nodiscard]] std::vector<std::string> endat_warning_names(uint16_t word);

// Memory area or additional-information selection of an MRS code (endat.md §3), "" if unknown.
[[nodiscard]] std::string_view mrs_name(uint8_t mrs) noexcept;

// Name of a manufacturer parameter word (global number 0..47, endat.md §4), "" if unnamed.
[[nodiscard]] std::string_view manufacturer_word_name(unsigned global_word) noexcept;

// Human meaning of one word read from the encoder, for ds1928ctl output: the word's name where
// known and its decoded value (status bits by name, temperatures in °C, position bits, ...).
// "" when nothing is known beyond the raw value. `mrs` is a memory area (0x04..0x07 reads) or an
// additional-information code (0x08..0x0B reads, `param` ignored).
[[nodiscard]] std::string describe_word(uint8_t mrs, uint8_t param, uint16_t value);

// Temperature words are in 0.1 K (endat.md §3): °C = raw × 0.1 − 273.2.
[[nodiscard]] constexpr double temperature_celsius(uint16_t raw) noexcept {
  return raw * 0.1 - 273.2;
}
// Inverse, rounded to the nearest 0.1 K and clamped to the word's range.
[[nodiscard]] uint16_t temperature_raw(double celsius) noexcept;

}  // namespace ds1928::endat
