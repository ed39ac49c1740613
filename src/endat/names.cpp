#include "endat/names.hpp"

#include <array>
#include <cmath>
#include <cstdio>

#include "x20ds1928/error_bits.hpp"

namespace ds1928::endat {
namespace {

std::vector<std::string> labels(ErrorRegister reg, uint16_t word) {
  std::vector<std::string> out;
  for (const SetErrorBit& b : set_error_bits(reg, word)) out.push_back(b.label());
  return out;
}

}  // namespace

std::vector<std::string> endat_error_names(uint16_t word) {
  return labels(ErrorRegister::EnDatError, word);
}
std::vector<std::string> endat_warning_names(uint16_t word) {
  return labels(ErrorRegister::EnDatWarning, word);
}

std::string_view mrs_name(uint8_t mrs) noexcept {
  switch (mrs) {
    case 0xA1:
      return "manufacturer parameters, page 0 (words 0-15)";
    case 0xA3:
      return "manufacturer parameters, page 1 (words 16-31)";
    case 0xA5:
      return "manufacturer parameters, page 2 (words 32-47)";
    case 0xA7:
      return "operating parameters";
    case 0xA9:
      return "OEM parameters, area 1";
    case 0xAB:
      return "OEM parameters, area 2";
    case 0xAD:
      return "OEM parameters, area 3";
    case 0xAF:
      return "OEM parameters, area 4";
    case 0xB1:
      return "compensation values, area 1";
    case 0xB3:
      return "compensation values, area 2";
    case 0xB5:
      return "compensation values, area 3";
    case 0xB7:
      return "compensation values, area 4";
    case 0xB9:
      return "operating status";
    case 0xBB:
      return "operating parameters 2";
    case 0xBD:
      return "EnDat 2.2 parameters of the manufacturer";
    case 0xBF:
      return "section 2";
    case 0x40:
      return "additional information 1: none";
    case 0x41:
      return "additional information 1: diagnosis";
    case 0x42:
      return "additional information 1: position value 2, word 1";
    case 0x43:
      return "additional information 1: position value 2, word 2";
    case 0x44:
      return "additional information 1: position value 2, word 3";
    case 0x45:
      return "additional information 1: memory parameter, word 1";
    case 0x46:
      return "additional information 1: memory parameter, word 2";
    case 0x47:
      return "additional information 1: MRS acknowledge";
    case 0x48:
      return "additional information 1: test command";
    case 0x49:
      return "additional information 1: test value, word 1";
    case 0x4A:
      return "additional information 1: test value, word 2";
    case 0x4B:
      return "additional information 1: test value, word 3";
    case 0x4C:
      return "additional information 1: temperature 1";
    case 0x4D:
      return "additional information 1: temperature 2";
    case 0x4E:
      return "additional information 1: additional sensors";
    case 0x4F:
      return "additional information 1: stop";
    case 0x50:
      return "additional information 2: none";
    case 0x51:
      return "additional information 2: commutation";
    case 0x52:
      return "additional information 2: acceleration";
    case 0x53:
      return "additional information 2: commutation and acceleration";
    case 0x54:
      return "additional information 2: limit position signals";
    case 0x55:
      return "additional information 2: limit position signals and acceleration";
    case 0x56:
      return "additional information 2: asynchronous position, word 1";
    case 0x57:
      return "additional information 2: asynchronous position, word 2";
    case 0x58:
      return "additional information 2: asynchronous position, word 3";
    case 0x59:
      return "additional information 2: operating status error sources";
    case 0x5B:
      return "additional information 2: time stamp";
    case 0x5F:
      return "additional information 2: stop";
    default:
      return {};
  }
}

std::string_view manufacturer_word_name(unsigned w) noexcept {
  switch (w) {
    case 4:
      return "mask 0";
    case 5:
      return "mask 1";
    case 6:
      return "mask 2";
    case 7:
      return "mask 3";
    case 8:
      return "EnDat version";
    case 13:
      return "clock pulses for the position value";
    case 14:
      return "encoder type";
    case 15:
      return "signal periods per revolution, low word";
    case 16:
      return "signal periods per revolution, high word";
    case 17:
      return "distinguishable revolutions";
    case 20:
      return "measuring steps per revolution, low word";
    case 21:
      return "measuring steps per revolution, high word";
    case 24:
      return "ID number, ASCII part";
    case 25:
      return "ID number, low word";
    case 26:
      return "ID number, high word";
    case 27:
      return "serial number, ASCII prefix / binary bits 7..0";
    case 28:
      return "serial number, binary bits 23..8";
    case 29:
      return "serial number, binary bits 31..24 / ASCII suffix";
    case 36:
      return "support of warnings";
    case 37:
      return "EnDat command set";
    case 47:
      return "checksum";
    default:
      return {};
  }
}

namespace {

// The meanings of the set bits (the table's words for people), reserved ones by their label.
std::vector<std::string> meanings(ErrorRegister reg, uint16_t word) {
  std::vector<std::string> out;
  for (const SetErrorBit& b : set_error_bits(reg, word))
    out.push_back(b.info != nullptr ? std::string(b.info->meaning) : b.label());
  return out;
}

std::string join(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string out;
  for (const auto& n : names) {
    if (!out.empty()) out += ", ";
    out += n;
  }
  return out;
}

std::string celsius_text(uint16_t raw) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f °C", temperature_celsius(raw));
  return buf;
}

char printable_or_dot(unsigned c) {
  return c >= 0x20 && c < 0x7F ? static_cast<char>(c) : '.';
}

}  // namespace

std::string describe_word(uint8_t mrs, uint8_t param, uint16_t value) {
  if (mrs == 0xA1 || mrs == 0xA3 || mrs == 0xA5) {
    const unsigned global = static_cast<unsigned>((mrs - 0xA1) / 2 * 16 + param);
    const std::string name(manufacturer_word_name(global));
    if (param >= 16 || name.empty()) return {};
    switch (global) {
      case 13:
        return name + ": " + std::to_string(value & 0x3F) + " bits";
      case 14:
        return name + ": " + ((value & 0x8000) != 0 ? "rotary" : "linear");
      case 17:
        return name + ": " + (value == 0 ? std::string("singleturn") : std::to_string(value));
      case 24:
        return name + ": \"" + printable_or_dot(value >> 8u) + printable_or_dot(value & 0xFFu) +
               "\"";
      case 37:
        return name + ": " + ((value & 3u) == 1u ? "EnDat 2.2" : "EnDat 2.1");
      default:
        return name;
    }
  }
  if (mrs == 0xA7 && param == 6) return "temperature warning threshold: " + celsius_text(value);
  if (mrs == 0xB9) {
    switch (param) {
      case 0:
        return "errors: " + join(meanings(ErrorRegister::EnDatError, value));
      case 1:
        return "warnings: " + join(meanings(ErrorRegister::EnDatWarning, value));
      case 2:
        return "write protection";
      case 3:
        return "configuration";
      default:
        return {};
    }
  }
  if (mrs == 0x4C || mrs == 0x4D) return std::string(mrs_name(mrs)) + ": " + celsius_text(value);
  if (mrs == 0x59)
    return "operating status errors: " + join(meanings(ErrorRegister::EnDatError, value));
  if (mrs >= 0x40 && mrs <= 0x5F) return std::string(mrs_name(mrs));
  return {};
}

uint16_t temperature_raw(double celsius) noexcept {
  const double raw = std::round((celsius + 273.2) * 10.0);
  if (!(raw > 0.0)) return 0;  // also NaN
  if (raw > 65535.0) return 65535;
  return static_cast<uint16_t>(raw);
}

}  // namespace ds1928::endat
