#include "x20ds1928/error_bits.hpp"

#include <algorithm>

namespace ds1928 {
namespace {

using R = ErrorRegister;
using C = ErrorClass;
using L = ErrorLed;

// The datasheet states a remedy for EnDatParSetError and EnDatRefWarning, and one for each
// register of the encoder's words (§11.6.2.1: "must be serviced", §11.6.2.2: "should be checked
// at once"); the other remedies are the project's, marked so in docs/registers.md.
constexpr std::array<ErrorBit, 19> kErrorBits{{
    {R::ErrorInfo, 0, "EncoderSupplyError", C::Fault, false, "encoder supply voltage too low",
     "check the encoder cable for a short and the encoder's current draw (the module supplies "
     "5 V / 300 mA); acknowledge with `ds1928ctl ack AXIS 0x01`",
     false, "11.6.1.1", L::Supply},
    {R::ErrorInfo, 2, "VssCheckError", C::Fault, true,
     "sin/cos track amplitude outside SinCosVssMin..SinCosVssMax; the module keeps the last good "
     "position",
     "check the sin/cos wires and shield and the configured Vss window (module.vss_min_mv / "
     "vss_max_mv); good values count again SinCosQuitTime after the fault clears",
     false, "11.6.1.1, 11.7.6", L::Io},
    {R::ErrorInfo, 3, "PositionError", C::Fault, true,
     "the position violates the application's requirements; the module keeps the last good "
     "position",
     "check the sin/cos track and the encoder's mounting; good values count again SinCosQuitTime "
     "after the fault clears",
     false, "11.6.1.1, 11.7.6", L::Io},
    {R::ErrorInfo, 4, "EnDatComError", C::Fault, false,
     "communication error on the EnDat interface (e.g. a wrong CRC)",
     "check the EnDat cable (clock and data pairs, length, shield); acknowledge with "
     "`ds1928ctl ack AXIS 0x10`",
     false, "11.6.1.1", L::System},
    {R::ErrorInfo, 5, "EnDatPosError", C::Fault, false,
     "the encoder rates its own position as invalid",
     "read the encoder's EnDatError word for the cause (`ds1928ctl status`); see the encoder's "
     "manual",
     false, "11.6.1.1", L::System},
    {R::ErrorInfo, 6, "EnDatParSetError", C::Fault, false,
     "the encoder's identification registers are inconsistent",
     "check the wiring or rescan the identification (`ds1928ctl endat rescan AXIS`, EnDatAck bit "
     "1)",
     true, "11.6.1.1", L::System},
    {R::ErrorInfo, 7, "EnDatRefWarning", C::Warning, false,
     "the incremental (sin/cos) position departed from the absolute EnDat position",
     "the position must be referenced again; acknowledge with `ds1928ctl ack AXIS 0x80`", true,
     "11.6.1.1", L::Io},
    {R::EnDatError, 0, "Lighting", C::Fault, false, "light source failed",
     "the system usually no longer works and must be serviced; see the encoder's manual", true,
     "11.6.2.1", L::None},
    {R::EnDatError, 1, "SignalAmplitude", C::Fault, false, "signal amplitude faulty",
     "the system usually no longer works and must be serviced; see the encoder's manual", true,
     "11.6.2.1", L::None},
    {R::EnDatError, 2, "PositionValue", C::Fault, false, "position value faulty",
     "the system usually no longer works and must be serviced; see the encoder's manual", true,
     "11.6.2.1", L::None},
    {R::EnDatError, 3, "Overvoltage", C::Fault, false, "encoder supply overvoltage",
     "the system usually no longer works and must be serviced; see the encoder's manual", true,
     "11.6.2.1", L::None},
    {R::EnDatError, 4, "Undervoltage", C::Fault, false, "encoder supply undervoltage",
     "the system usually no longer works and must be serviced; see the encoder's manual", true,
     "11.6.2.1", L::None},
    {R::EnDatError, 5, "Overcurrent", C::Fault, false, "encoder overcurrent",
     "the system usually no longer works and must be serviced; see the encoder's manual", true,
     "11.6.2.1", L::None},
    {R::EnDatError, 6, "Battery", C::Fault, false, "battery must be replaced",
     "replace the encoder's battery; then acknowledge (`ds1928ctl ack AXIS --register`)", false,
     "11.6.2.1", L::None},
    {R::EnDatWarning, 0, "FrequencyCollision", C::Warning, false, "frequency collision",
     "the encoder still works but must be checked at once; see the encoder's manual", true,
     "11.6.2.2", L::None},
    {R::EnDatWarning, 1, "Temperature", C::Warning, false, "temperature exceeded",
     "the encoder still works but must be checked at once: cool the encoder, see its manual", true,
     "11.6.2.2", L::None},
    {R::EnDatWarning, 2, "LightingReserve", C::Warning, false,
     "light control reserve needed (the light source is ageing)",
     "the encoder still works but must be checked at once; plan its replacement", true, "11.6.2.2",
     L::None},
    {R::EnDatWarning, 3, "BatteryCharge", C::Warning, false, "battery charge low",
     "the encoder still works but must be checked at once: replace the battery soon", true,
     "11.6.2.2", L::None},
    {R::EnDatWarning, 4, "ReferencePoint", C::Information, false, "reference point not reached",
     "move the axis over the reference point", false, "11.6.2.2", L::None},
}};

std::string escape_cell(std::string_view s) {
  std::string out;
  for (const char c : s) {
    if (c == '|') out += '\\';
    out += c;
  }
  return out;
}

std::string_view e_led_markdown(ErrorLed led) {
  switch (led) {
    case ErrorLed::Supply:
      return "on";
    case ErrorLed::Io:
      return "single flash";
    case ErrorLed::System:
      return "double flash";
    case ErrorLed::None:
      break;
  }
  return "—";
}

}  // namespace

std::span<const ErrorBit> error_bits() noexcept {
  return kErrorBits;
}

const ErrorBit* find_error_bit(ErrorRegister reg, unsigned bit) noexcept {
  for (const ErrorBit& b : kErrorBits)
    if (b.reg == reg && b.bit == bit) return &b;
  return nullptr;
}

const ErrorBit* find_error_bit(std::string_view name) noexcept {
  for (const ErrorBit& b : kErrorBits)
    if (b.name == name) return &b;
  return nullptr;
}

std::string_view to_string(ErrorRegister reg) noexcept {
  switch (reg) {
    case ErrorRegister::ErrorInfo:
      return "ErrorInfo";
    case ErrorRegister::EnDatError:
      return "EnDatError";
    case ErrorRegister::EnDatWarning:
      return "EnDatWarning";
  }
  return "?";
}

std::string_view to_string(ErrorClass cls) noexcept {
  switch (cls) {
    case ErrorClass::Fault:
      return "fault";
    case ErrorClass::Warning:
      return "warning";
    case ErrorClass::Information:
      return "information";
  }
  return "?";
}

ErrorPolicy error_policy(const ErrorMasks& on, const ErrorMasks& off) noexcept {
  ErrorPolicy p;
  for (const ErrorBit& b : kErrorBits) {
    const auto r = static_cast<std::size_t>(b.reg);
    const auto m = static_cast<uint16_t>(1u << b.bit);
    ErrorEffect e = b.default_effect();
    if ((on[r] & m) != 0) e = b.analogue ? ErrorEffect::Hold : ErrorEffect::Invalidate;
    if ((off[r] & m) != 0) e = ErrorEffect::Flag;
    if (e == ErrorEffect::Invalidate) p.invalidate[r] |= m;
    if (e == ErrorEffect::Hold) p.hold[r] |= m;
    if (b.cls == ErrorClass::Fault) p.fault[r] |= m;
    if (b.cls == ErrorClass::Warning) p.warning[r] |= m;
  }
  return p;
}

std::string SetErrorBit::label() const {
  if (info != nullptr) return std::string(info->name);
  return std::string(to_string(reg)) + " reserved bit " + std::to_string(bit);
}

std::vector<SetErrorBit> set_error_bits(ErrorRegister reg, uint32_t word) {
  std::vector<SetErrorBit> out;
  for (unsigned bit = 0; bit < register_width(reg); ++bit)
    if ((word & (1u << bit)) != 0) out.push_back({reg, bit, find_error_bit(reg, bit)});
  return out;
}

std::vector<SetErrorBit> set_error_bits(const ErrorWords& w) {
  std::vector<SetErrorBit> out;
  for (std::size_t r = 0; r < kErrorRegisters; ++r) {
    const auto reg = static_cast<ErrorRegister>(r);
    for (const SetErrorBit& b : set_error_bits(reg, w[reg])) out.push_back(b);
  }
  return out;
}

std::string error_bit_list(ErrorRegister reg, uint32_t word) {
  std::string out;
  for (const SetErrorBit& b : set_error_bits(reg, word)) {
    if (!out.empty()) out += ", ";
    out += b.label();
  }
  return out.empty() ? "none" : out;
}

std::string error_bits_markdown() {
  std::string out =
      "| register | bit | name | class | default effect | e-LED | meaning | remedy | § |\n"
      "|---|---|---|---|---|---|---|---|---|\n";
  for (const ErrorBit& b : kErrorBits) {
    const std::string_view effect = b.default_effect() == ErrorEffect::Invalidate ? "module_error"
                                    : b.default_effect() == ErrorEffect::Hold     ? "hold (stale)"
                                                                                  : "flag";
    out += "| " + std::string(to_string(b.reg)) + " | " + std::to_string(b.bit) + " | " +
           std::string(b.name) + " | " + std::string(to_string(b.cls)) + " | " +
           std::string(effect) + " | " + std::string(e_led_markdown(b.led)) + " | " +
           escape_cell(b.meaning) + " | " + escape_cell(b.remedy) +
           (b.remedy_from_datasheet ? "" : " ¹") + " | " + std::string(b.section) + " |\n";
  }
  return out;
}

}  // namespace ds1928
