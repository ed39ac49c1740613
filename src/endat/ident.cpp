#include "endat/ident.hpp"

namespace ds1928::endat {
namespace {

bool printable(char c) noexcept {
  return c > ' ' && c < 0x7F;
}

}  // namespace

std::string IdNumber::to_string() const {
  std::string s = std::to_string(binary);
  if (printable(text[0]) || printable(text[1])) {
    s += '-';
    for (char c : text) {
      if (printable(c)) s += c;
    }
  }
  return s;
}

std::string SerialNumber::to_string() const {
  std::string s;
  if (printable(prefix)) s += prefix;
  s += std::to_string(binary);
  if (printable(suffix)) s += suffix;
  return s;
}

unsigned bits_for(uint64_t n) noexcept {
  unsigned bits = 0;
  while (bits < 64 && (uint64_t{1} << bits) < n) ++bits;
  return bits;
}

CommandSet command_set_from_word(uint16_t word37) noexcept {
  return (word37 & 0x3u) == 0x1u ? CommandSet::EnDat22 : CommandSet::EnDat21;
}

Result<Identification> decode_identification(
    std::span<const uint16_t, kManufacturerWords> w) noexcept {
  using namespace manuf_word;
  Identification id;
  id.version_word = w[kEnDatVersion];
  id.command_set_word = w[kCommandSet];
  id.command_set = command_set_from_word(w[kCommandSet]);
  id.type = (w[kEncoderType] & 0x8000u) != 0 ? EncoderType::Rotary : EncoderType::Linear;
  id.position_bits = w[kPositionBits] & 0x3Fu;
  id.signal_periods = static_cast<uint32_t>(w[kSignalPeriodsLow]) |
                      (static_cast<uint32_t>(w[kSignalPeriodsHigh]) << 16);
  id.revolutions = w[kRevolutions];
  id.steps_per_revolution =
      static_cast<uint32_t>(w[kStepsLow]) | (static_cast<uint32_t>(w[kStepsHigh]) << 16);
  id.id.text[0] = static_cast<char>(w[kIdText] >> 8);
  id.id.text[1] = static_cast<char>(w[kIdText] & 0xFF);
  id.id.binary = static_cast<uint32_t>(w[kIdLow]) | (static_cast<uint32_t>(w[kIdHigh]) << 16);
  id.serial.prefix = static_cast<char>(w[kSerial0] & 0xFF);
  id.serial.binary = static_cast<uint32_t>(w[kSerial0] >> 8) |
                     (static_cast<uint32_t>(w[kSerial1]) << 8) |
                     (static_cast<uint32_t>(w[kSerial2] & 0xFF) << 24);
  id.serial.suffix = static_cast<char>(w[kSerial2] >> 8);
  id.warnings_supported = w[kWarningsSupported];
  id.checksum = w[kChecksum];

  if (id.position_bits == 0 || id.position_bits > 48) return Errc::invalid_identification;
  if (id.type == EncoderType::Rotary) {
    if (id.steps_per_revolution == 0) return Errc::invalid_identification;
    const unsigned needed = bits_for(id.steps_per_revolution) + bits_for(id.revolutions);
    if (needed > id.position_bits) return Errc::invalid_identification;
  }
  return id;
}

void encode_identification(const Identification& id,
                           std::span<uint16_t, kManufacturerWords> w) noexcept {
  using namespace manuf_word;
  w[kEnDatVersion] = id.version_word;
  w[kCommandSet] = static_cast<uint16_t>((id.command_set_word & ~0x3u) |
                                         (id.command_set == CommandSet::EnDat22 ? 0x1u : 0x0u));
  w[kEncoderType] = static_cast<uint16_t>((w[kEncoderType] & 0x7FFFu) |
                                          (id.type == EncoderType::Rotary ? 0x8000u : 0u));
  w[kPositionBits] = static_cast<uint16_t>((w[kPositionBits] & ~0x3Fu) | (id.position_bits & 0x3F));
  w[kSignalPeriodsLow] = static_cast<uint16_t>(id.signal_periods & 0xFFFF);
  w[kSignalPeriodsHigh] = static_cast<uint16_t>(id.signal_periods >> 16);
  w[kRevolutions] = id.revolutions;
  w[kStepsLow] = static_cast<uint16_t>(id.steps_per_revolution & 0xFFFF);
  w[kStepsHigh] = static_cast<uint16_t>(id.steps_per_revolution >> 16);
  w[kIdText] = static_cast<uint16_t>((static_cast<uint8_t>(id.id.text[0]) << 8) |
                                     static_cast<uint8_t>(id.id.text[1]));
  w[kIdLow] = static_cast<uint16_t>(id.id.binary & 0xFFFF);
  w[kIdHigh] = static_cast<uint16_t>(id.id.binary >> 16);
  w[kSerial0] = static_cast<uint16_t>(static_cast<uint8_t>(id.serial.prefix) |
                                      ((id.serial.binary & 0xFF) << 8));
  w[kSerial1] = static_cast<uint16_t>((id.serial.binary >> 8) & 0xFFFF);
  w[kSerial2] = static_cast<uint16_t>(((id.serial.binary >> 24) & 0xFF) |
                                      (static_cast<uint8_t>(id.serial.suffix) << 8));
  w[kWarningsSupported] = id.warnings_supported;
}

}  // namespace ds1928::endat
