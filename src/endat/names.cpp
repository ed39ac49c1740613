#include "endat/names.hpp"

#include <array>
#include <cmath>

namespace ds1928::endat {
namespace {

constexpr std::array<std::string_view, 7> kErrorBits{
    "light source failed", "signal amplitude", "position value",         "overvoltage",
    "undervoltage",        "overcurrent",      "battery change required"};
constexpr std::array<std::string_view, 5> kWarningBits{
    "frequency collision", "temperature exceeded", "light control reserve", "battery charge low",
    "reference point not reached"};
constexpr std::array<std::string_view, 8> kErrorInfoBits{"EncoderSupplyError", "",
                                                         "VssCheckError",      "PositionError",
                                                         "EnDatComError",      "EnDatPosError",
                                                         "EnDatParSetError",   "EnDatRefWarning"};

template <std::size_t N>
std::vector<std::string> names_of(uint32_t word, unsigned width,
                                  const std::array<std::string_view, N>& table) {
  std::vector<std::string> out;
  for (unsigned bit = 0; bit < width; ++bit) {
    if ((word & (1u << bit)) == 0) continue;
    if (bit < N && !table[bit].empty()) {
      out.emplace_back(table[bit]);
    } else {
      out.push_back("reserved bit " + std::to_string(bit));
    }
  }
  return out;
}

}  // namespace

std::string_view endat_error_bit_name(unsigned bit) noexcept {
  return bit < kErrorBits.size() ? kErrorBits[bit] : std::string_view{};
}
std::string_view endat_warning_bit_name(unsigned bit) noexcept {
  return bit < kWarningBits.size() ? kWarningBits[bit] : std::string_view{};
}
std::string_view error_info_bit_name(unsigned bit) noexcept {
  return bit < kErrorInfoBits.size() ? kErrorInfoBits[bit] : std::string_view{};
}

std::vector<std::string> endat_error_names(uint16_t word) {
  return names_of(word, 16, kErrorBits);
}
std::vector<std::string> endat_warning_names(uint16_t word) {
  return names_of(word, 16, kWarningBits);
}
std::vector<std::string> error_info_names(uint8_t bits) {
  return names_of(bits, 8, kErrorInfoBits);
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

uint16_t temperature_raw(double celsius) noexcept {
  const double raw = std::round((celsius + 273.2) * 10.0);
  if (!(raw > 0.0)) return 0;  // also NaN
  if (raw > 65535.0) return 65535;
  return static_cast<uint16_t>(raw);
}

}  // namespace ds1928::endat
