#include "core/sdo_abort.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>

namespace ds1928 {
namespace {

using namespace sdo_abort;

// CiA 301 §7.2.4.3.17, table "SDO abort codes" (EPSG DS 301 uses the same codes and texts).
constexpr std::array kTable{
    SdoAbortEntry{kToggleBit, "toggle bit not alternated"},
    SdoAbortEntry{kTimeout, "SDO protocol timed out"},
    SdoAbortEntry{kUnknownCommand, "client/server command specifier not valid or unknown"},
    SdoAbortEntry{kInvalidBlockSize, "invalid block size"},
    SdoAbortEntry{kInvalidSequence, "invalid sequence number"},
    SdoAbortEntry{kCrcError, "CRC error"},
    SdoAbortEntry{kOutOfMemory, "out of memory"},
    SdoAbortEntry{kUnsupportedAccess, "unsupported access to an object"},
    SdoAbortEntry{kWriteOnly, "attempt to read a write only object"},
    SdoAbortEntry{kReadOnly, "attempt to write a read only object"},
    SdoAbortEntry{kNoObject, "object does not exist in the object dictionary"},
    SdoAbortEntry{kNotMappable, "object cannot be mapped to the PDO"},
    SdoAbortEntry{kPdoLengthExceeded,
                  "the number and length of the objects to be mapped would exceed PDO length"},
    SdoAbortEntry{kParameterIncompatible, "general parameter incompatibility"},
    SdoAbortEntry{kInternalIncompatible, "general internal incompatibility in the device"},
    SdoAbortEntry{kHardwareError, "access failed due to a hardware error"},
    SdoAbortEntry{kTypeLength,
                  "data type does not match, length of service parameter does not match"},
    SdoAbortEntry{kLengthTooHigh, "data type does not match, length of service parameter too high"},
    SdoAbortEntry{kLengthTooLow, "data type does not match, length of service parameter too low"},
    SdoAbortEntry{kNoSubindex, "sub-index does not exist"},
    SdoAbortEntry{kOutOfRange, "invalid value for parameter"},
    SdoAbortEntry{kValueTooHigh, "value of parameter written too high"},
    SdoAbortEntry{kValueTooLow, "value of parameter written too low"},
    SdoAbortEntry{kMaxBelowMin, "maximum value is less than minimum value"},
    SdoAbortEntry{kNoResource, "resource not available: SDO connection"},
    SdoAbortEntry{kGeneral, "general error"},
    SdoAbortEntry{kCannotStore, "data cannot be transferred or stored to the application"},
    SdoAbortEntry{kLocalControl,
                  "data cannot be transferred or stored to the application because of local "
                  "control"},
    SdoAbortEntry{kDeviceState,
                  "data cannot be transferred or stored to the application because of the present "
                  "device state"},
    SdoAbortEntry{kNoObjectDictionary,
                  "object dictionary dynamic generation fails or no object dictionary is present"},
    SdoAbortEntry{kNoData, "no data available"},
};
static_assert(std::is_sorted(kTable.begin(), kTable.end(),
                             [](const SdoAbortEntry& a, const SdoAbortEntry& b) {
                               return a.code < b.code;
                             }),
              "the lookup below is a binary search");

[[nodiscard]] const SdoAbortEntry* find(uint32_t code) noexcept {
  const auto* it = std::lower_bound(kTable.begin(), kTable.end(), code,
                                    [](const SdoAbortEntry& e, uint32_t c) { return e.code < c; });
  return it != kTable.end() && it->code == code ? it : nullptr;
}

class SdoAbortCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "sdo-abort"; }
  std::string message(int ev) const override {
    const auto code = static_cast<uint32_t>(ev);
    char head[32];
    std::snprintf(head, sizeof head, "SDO abort 0x%08X: ", code);
    return std::string(head) + std::string(sdo_abort_name(code));
  }
};

}  // namespace

std::span<const SdoAbortEntry> sdo_abort_table() noexcept {
  return kTable;
}

std::string_view sdo_abort_name(uint32_t code) noexcept {
  const SdoAbortEntry* e = find(code);
  return e ? e->name : std::string_view("unknown abort code");
}

bool sdo_abort_known(uint32_t code) noexcept {
  return find(code) != nullptr;
}

const std::error_category& sdo_abort_category() noexcept {
  static const SdoAbortCategory category;
  return category;
}

}  // namespace ds1928
