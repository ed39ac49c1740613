// SDO abort codes: the one table of the project. CiA 301 §7.2.4.3.17 defines them for CANopen
// (CAN-I/O bus controllers) and EPSG DS 301 takes the same codes for POWERLINK's ASnd SDO, so
// both buses, both simulators and every message that shows an abort code use this table.
//
// An abort code travels as a std::error_code of sdo_abort_category() whose value() is the
// code's bit pattern; its message() is "SDO abort 0x06020000: object does not exist in the
// object dictionary", or "... : unknown abort code" for a code outside the table.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <system_error>

namespace ds1928 {

namespace sdo_abort {
inline constexpr uint32_t kToggleBit = 0x0503'0000;         // toggle bit not alternated
inline constexpr uint32_t kTimeout = 0x0504'0000;           // SDO protocol timed out
inline constexpr uint32_t kUnknownCommand = 0x0504'0001;    // command specifier unknown
inline constexpr uint32_t kInvalidBlockSize = 0x0504'0002;  // block mode: invalid block size
inline constexpr uint32_t kInvalidSequence = 0x0504'0003;   // invalid sequence number
inline constexpr uint32_t kCrcError = 0x0504'0004;          // block mode: CRC error
inline constexpr uint32_t kOutOfMemory = 0x0504'0005;
inline constexpr uint32_t kUnsupportedAccess = 0x0601'0000;
inline constexpr uint32_t kWriteOnly = 0x0601'0001;  // attempt to read a write-only object
inline constexpr uint32_t kReadOnly = 0x0601'0002;   // attempt to write a read-only object
inline constexpr uint32_t kNoObject = 0x0602'0000;   // object does not exist
inline constexpr uint32_t kNotMappable = 0x0604'0041;
inline constexpr uint32_t kPdoLengthExceeded = 0x0604'0042;
inline constexpr uint32_t kParameterIncompatible = 0x0604'0043;
inline constexpr uint32_t kInternalIncompatible = 0x0604'0047;
inline constexpr uint32_t kHardwareError = 0x0606'0000;
inline constexpr uint32_t kTypeLength = 0x0607'0010;  // data type / length does not match
inline constexpr uint32_t kLengthTooHigh = 0x0607'0012;
inline constexpr uint32_t kLengthTooLow = 0x0607'0013;
inline constexpr uint32_t kNoSubindex = 0x0609'0011;
inline constexpr uint32_t kOutOfRange = 0x0609'0030;  // invalid value for parameter
inline constexpr uint32_t kValueTooHigh = 0x0609'0031;
inline constexpr uint32_t kValueTooLow = 0x0609'0032;
inline constexpr uint32_t kMaxBelowMin = 0x0609'0036;
inline constexpr uint32_t kNoResource = 0x060A'0023;  // resource not available: SDO connection
inline constexpr uint32_t kGeneral = 0x0800'0000;
inline constexpr uint32_t kCannotStore = 0x0800'0020;  // data cannot be transferred or stored
inline constexpr uint32_t kLocalControl = 0x0800'0021;
inline constexpr uint32_t kDeviceState = 0x0800'0022;  // not possible in the present device state
inline constexpr uint32_t kNoObjectDictionary = 0x0800'0023;
inline constexpr uint32_t kNoData = 0x0800'0024;
}  // namespace sdo_abort

struct SdoAbortEntry {
  uint32_t code = 0;
  std::string_view name;  // the standard's text
};

// Every code above with its name, in ascending code order.
[[nodiscard]] std::span<const SdoAbortEntry> sdo_abort_table() noexcept;
// The standard's text for `code`, or "unknown abort code".
[[nodiscard]] std::string_view sdo_abort_name(uint32_t code) noexcept;
// Whether `code` is in the table.
[[nodiscard]] bool sdo_abort_known(uint32_t code) noexcept;

[[nodiscard]] const std::error_category& sdo_abort_category() noexcept;
[[nodiscard]] inline std::error_code make_sdo_abort_error(uint32_t code) noexcept {
  return {static_cast<int>(code), sdo_abort_category()};
}
// The abort code an error carries, if it is one of sdo_abort_category().
[[nodiscard]] inline std::optional<uint32_t> sdo_abort_code(std::error_code ec) noexcept {
  if (ec.category() != sdo_abort_category()) return std::nullopt;
  return static_cast<uint32_t>(ec.value());
}

}  // namespace ds1928
