// The X20DS1928's registers in one place (datasheet 002 §11, X20DS1928.md §2–§6): number, name,
// size, bus-controller default, direction, where function model 0 puts a cyclic register in the
// POWERLINK module block, where function model 254 puts it in the CAN objects, and the order in
// which a master writes the configuration at start. The POWERLINK process image and SDO sizes,
// the CAN-I/O object codec and start-up, the simulated module and docs/registers.md all read
// this table; nothing else states register facts.
// Pure: constexpr data, no allocation except catalogue_markdown().
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "core/module_image.hpp"
#include "core/module_settings.hpp"

namespace ds1928 {

enum class RegisterDirection : uint8_t {
  In,        // cyclic, module → master
  Out,       // cyclic, master → module
  Config,    // acyclic, written by the master (configuration)
  Command,   // acyclic write, self-clearing (EnDatAck)
  ReadOnly,  // acyclic read (identification, status)
};
[[nodiscard]] std::string_view to_string(RegisterDirection d) noexcept;

// Function models a register exists in.
enum ModelMask : uint8_t { kFm0 = 1, kFm254 = 2, kBothModels = 3 };

inline constexpr int8_t kNoOffset = -1;

struct RegisterInfo {
  uint16_t number = 0;  // datasheet register number of the first member
  uint8_t count = 1;    // family members (RxByte1..15: 15)
  uint8_t stride = 1;   // register-number step between members
  std::string_view name;
  uint8_t size = 1;  // bytes: 1, 2 or 4
  RegisterDirection direction = RegisterDirection::ReadOnly;
  uint8_t models = kBothModels;
  std::optional<uint32_t> default_value;  // bus-controller default (datasheet §11.9.4.1)
  // Function model 0, POWERLINK: byte offset inside the module's PRes (In) or PReq (Out) block;
  // for a family the first member's. AckErrorInfo follows the Tx bytes: offset + OutputMTU.
  int8_t fm0_offset = kNoOffset;
  bool fm0_after_tx_bytes = false;
  // Function model 254, CAN-I/O: the datasheet's offset inside the CAN objects — inputs 0..15
  // across the two 8-byte input objects, outputs 0..7 in the output object.
  int8_t can_offset = kNoOffset;
  uint8_t fm254_members = 0;  // family members under function model 254 (0 = count)
  uint8_t startup_order = 0;  // 1.. = written at start in this order; 0 = not written

  [[nodiscard]] constexpr bool cyclic() const noexcept {
    return direction == RegisterDirection::In || direction == RegisterDirection::Out;
  }
  [[nodiscard]] constexpr bool contains(uint16_t reg) const noexcept {
    return reg >= number && reg < number + count * stride && (reg - number) % stride == 0;
  }
  [[nodiscard]] constexpr uint8_t members(FunctionModel fm) const noexcept {
    return fm == FunctionModel::BusController && fm254_members != 0 ? fm254_members : count;
  }
};

// The whole table in datasheet order (cyclic first, then configuration, then acyclic reads).
[[nodiscard]] std::span<const RegisterInfo> register_catalogue() noexcept;

// The entry holding `reg` (a family member too), or nullptr.
[[nodiscard]] const RegisterInfo* find_register(uint16_t reg) noexcept;
// The size in bytes of `reg`, nullopt when the catalogue does not know it.
[[nodiscard]] std::optional<uint8_t> register_size(uint16_t reg) noexcept;

// Offsets the cyclic codecs use, taken from the catalogue (checked against it by a test).
namespace fm0 {
inline constexpr std::size_t kPositionHw = 0, kPositionLw = 4, kPosTime = 8, kPosCycle = 12,
                             kSdcLifeCount = 13, kErrorInfo = 14, kInputSequence = 15,
                             kRxBytes = 16;                      // PRes block
inline constexpr std::size_t kOutputSequence = 0, kTxBytes = 1;  // PReq block; AckErrorInfo after
}  // namespace fm0
namespace fm254 {
inline constexpr std::size_t kPositionHw = 0, kPositionLw = 4, kInputSequence = 8, kRxBytes = 9,
                             kErrorInfo = 14, kPosCycle = 15;  // over the two input objects
inline constexpr std::size_t kOutputSequence = 0, kTxBytes = 1, kAckErrorInfo = 6;
inline constexpr std::size_t kMaxMtu = 5;  // Rx/Tx bytes the CAN objects carry
}  // namespace fm254

// One acyclic write of the start-up configuration.
struct RegisterWrite {
  uint16_t reg = 0;
  uint8_t size = 1;
  uint32_t value = 0;
};
inline constexpr std::size_t kStartupWriteCount = 14;
// The configuration a master writes at start, in the catalogue's start-up order (EnDatMode last:
// the encoder is enabled once everything else is set).
[[nodiscard]] std::array<RegisterWrite, kStartupWriteCount> startup_writes(
    const ModuleSettings& settings) noexcept;

// The catalogue as the Markdown table of docs/registers.md.
[[nodiscard]] std::string catalogue_markdown();

}  // namespace ds1928
