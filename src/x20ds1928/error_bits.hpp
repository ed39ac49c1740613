// Every bit of the module's three error registers — ErrorInfo (§11.6.1.2), EnDatError
// (§11.6.2.1) and EnDatWarning (§11.6.2.2) — in one table: its name, class, meaning and remedy.
// Status output, the journal, the metrics, the HAL pins, the position's validity and
// docs/registers.md all take the bits from here.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace ds1928 {

enum class ErrorRegister : uint8_t { ErrorInfo = 0, EnDatError = 1, EnDatWarning = 2 };
inline constexpr std::size_t kErrorRegisters = 3;

// The datasheet's class of a bit: a fault stops the encoder's position from being trusted; a
// warning says the encoder still works but should be checked (§11.6.2.2); information reports a
// state without a defect.
enum class ErrorClass : uint8_t { Fault, Warning, Information };

// The module's red e-LED (datasheet §4 "Status-LEDs") groups the ErrorInfo bits by what it
// flashes: on for the encoder supply, single flash for an I/O error (the sin/cos track: wire break,
// position, reference), double flash for a system error (EnDat communication, position,
// parameters). The encoder's own words (EnDatError, EnDatWarning) light nothing of their own.
enum class ErrorLed : uint8_t { None, Supply, Io, System };

// What a set bit does to the published position.
enum class ErrorEffect : uint8_t {
  Flag,        // flagged (status, pins, metrics); the position stays valid
  Hold,        // the last good position is kept and published stale (§11.7.6, analogue errors)
  Invalidate,  // the axis is module_error
};

struct ErrorBit {
  ErrorRegister reg;
  uint8_t bit;
  std::string_view name;  // unique over the three registers (the metrics' bit label)
  ErrorClass cls;
  bool analogue;  // an error of the sin/cos interface: the module holds the last good value
  std::string_view meaning;
  std::string_view remedy;
  bool remedy_from_datasheet;  // false: the datasheet states none, the remedy is the project's
  std::string_view section;    // datasheet section
  ErrorLed led;                // what the e-LED flashes while it is set

  // The datasheet's class as an effect: faults invalidate (analogue ones hold), warnings and
  // information are flagged only.
  [[nodiscard]] constexpr ErrorEffect default_effect() const noexcept {
    if (cls != ErrorClass::Fault) return ErrorEffect::Flag;
    return analogue ? ErrorEffect::Hold : ErrorEffect::Invalidate;
  }
};

[[nodiscard]] std::span<const ErrorBit> error_bits() noexcept;
// nullptr for a reserved bit.
[[nodiscard]] const ErrorBit* find_error_bit(ErrorRegister reg, unsigned bit) noexcept;
[[nodiscard]] const ErrorBit* find_error_bit(std::string_view name) noexcept;

[[nodiscard]] std::string_view to_string(ErrorRegister reg) noexcept;
[[nodiscard]] std::string_view to_string(ErrorClass cls) noexcept;
[[nodiscard]] constexpr unsigned register_width(ErrorRegister reg) noexcept {
  return reg == ErrorRegister::ErrorInfo ? 8 : 16;
}

// Per register (indexed by ErrorRegister), a mask of bits.
using ErrorMasks = std::array<uint16_t, kErrorRegisters>;

// The effect of every bit on one axis: the datasheet's class, then the axis' overrides
// (axes[].invalidate_on: `on` bits invalidate — hold if analogue —, `off` bits are flagged only).
struct ErrorPolicy {
  ErrorMasks invalidate{};
  ErrorMasks hold{};
  ErrorMasks fault{};    // class fault (reserved bits count as nothing)
  ErrorMasks warning{};  // class warning
};
[[nodiscard]] ErrorPolicy error_policy(const ErrorMasks& on = {},
                                       const ErrorMasks& off = {}) noexcept;

// The three words of one axis.
struct ErrorWords {
  uint8_t error_info = 0;
  uint16_t endat_error = 0;
  uint16_t endat_warning = 0;
  [[nodiscard]] constexpr uint16_t operator[](ErrorRegister r) const noexcept {
    switch (r) {
      case ErrorRegister::ErrorInfo:
        return error_info;
      case ErrorRegister::EnDatError:
        return endat_error;
      case ErrorRegister::EnDatWarning:
        return endat_warning;
    }
    return 0;
  }
  friend constexpr bool operator==(const ErrorWords&, const ErrorWords&) = default;
};

// What the set bits make of a position. Pure and allocation-free (cycle thread).
struct ErrorAssessment {
  bool invalidate = false;
  bool hold = false;
  bool fault = false;    // a fault-class bit is set
  bool warning = false;  // a warning-class bit is set
};
[[nodiscard]] constexpr ErrorAssessment assess(const ErrorPolicy& p, const ErrorWords& w) noexcept {
  ErrorAssessment a;
  for (std::size_t r = 0; r < kErrorRegisters; ++r) {
    const uint16_t word = w[static_cast<ErrorRegister>(r)];
    a.invalidate |= (word & p.invalidate[r]) != 0;
    a.hold |= (word & p.hold[r]) != 0;
    a.fault |= (word & p.fault[r]) != 0;
    a.warning |= (word & p.warning[r]) != 0;
  }
  return a;
}

// One set bit: its table row, or nullptr for a reserved bit.
struct SetErrorBit {
  ErrorRegister reg;
  unsigned bit;
  const ErrorBit* info;
  [[nodiscard]] std::string label() const;  // the name, or "<register> reserved bit N"
};
// The set bits of `word` in `reg`, lowest first; all set bits of the three words.
[[nodiscard]] std::vector<SetErrorBit> set_error_bits(ErrorRegister reg, uint32_t word);
[[nodiscard]] std::vector<SetErrorBit> set_error_bits(const ErrorWords& w);
// Names of the set bits, "none" when none: for log lines.
[[nodiscard]] std::string error_bit_list(ErrorRegister reg, uint32_t word);

// docs/registers.md's error table (checked by x20ds1928_error_bits_test).
[[nodiscard]] std::string error_bits_markdown();

}  // namespace ds1928
