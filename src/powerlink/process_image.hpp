// Process-data image of one Controlled Node: where each X20DS1928 (function model 0) sits in the
// PRes and PReq payloads. Shared by the Managing Node and the simulated CN, so both ends agree.
// Default layout (docs/powerlink.md §Process image): modules in ascending slot order, packed,
// starting at payload offset 0. A module may be placed elsewhere (ModuleSpec::pres_offset /
// preq_offset); the others keep their default offsets, so overriding one never moves another.
//   PRes per module: PositionHW u32 | PositionLW u32 | PosTime u32 | PosCycle i8 |
//                    SDCLifeCount i8 | ErrorInfo u8 | InputSequence u8 | RxBytes[InputMTU]
//   PReq per module: OutputSequence u8 | TxBytes[OutputMTU] | AckErrorInfo u8
// Pure: no I/O, no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include "powerlink/errors.hpp"
#include "x20ds1928/module_image.hpp"

namespace ds1928::powerlink {

inline constexpr std::size_t kMaxModulesPerNode = 16;
inline constexpr std::size_t kPresModuleFixedSize = 16;
inline constexpr std::size_t kPreqModuleFixedSize = 2;

[[nodiscard]] constexpr std::size_t pres_module_size(uint8_t input_mtu) noexcept {
  return kPresModuleFixedSize + input_mtu;
}
[[nodiscard]] constexpr std::size_t preq_module_size(uint8_t output_mtu) noexcept {
  return kPreqModuleFixedSize + output_mtu;
}

struct ModuleSpec {
  // A constructor, not an aggregate: `ModuleSpec{slot, in, out}` stays warning-free.
  constexpr ModuleSpec(uint8_t slot_ = 1, uint8_t input_mtu_ = 7, uint8_t output_mtu_ = 7,
                       std::optional<uint16_t> pres_offset_ = std::nullopt,
                       std::optional<uint16_t> preq_offset_ = std::nullopt) noexcept
      : slot(slot_),
        input_mtu(input_mtu_),
        output_mtu(output_mtu_),
        pres_offset(pres_offset_),
        preq_offset(preq_offset_) {}

  uint8_t slot;
  uint8_t input_mtu;
  uint8_t output_mtu;
  std::optional<uint16_t> pres_offset;  // block start in the PRes payload; default: packed
  std::optional<uint16_t> preq_offset;  // block start in the PReq payload; default: packed
};

// Why make_layout() refused, with the slots involved (for a message naming them).
struct LayoutIssue {
  uint8_t slot = 0;        // the module at fault
  uint8_t other_slot = 0;  // the module it collides with (overlap), else 0
  bool in_preq = false;    // overlap/overflow in the PReq (else the PRes)
};

// A module's registers, each at its own offset when the image comes from the CN's PDO mapping
// (powerlink/pdo_image.hpp); the Rx/Tx bytes are numbered separately.
enum class ImageField : uint8_t {
  kPositionHW,
  kPositionLW,
  kPosTime,
  kPosCycle,
  kSdcLifeCount,
  kErrorInfo,
  kInputSequence,
  kOutputSequence,
  kAckErrorInfo,
  // The additional-information channels (§11.8.3): only from a PDO mapping that maps them.
  kInfoOk,
  kInfo1,
  kInfo2,
  kInfo3,
  kInfo4,
};
inline constexpr std::size_t kImageFieldCount = 14;
inline constexpr uint16_t kNotMapped = 0xFFFF;
struct FieldOffsets {
  FieldOffsets() noexcept {
    fixed.fill(kNotMapped);
    rx.fill(kNotMapped);
    tx.fill(kNotMapped);
  }
  std::array<uint16_t, kImageFieldCount> fixed{};  // byte offset per ImageField
  std::array<uint16_t, kMaxFlatstreamMtu> rx{};    // RxByte1.. in the PRes
  std::array<uint16_t, kMaxFlatstreamMtu> tx{};    // TxByte1.. in the PReq
  uint16_t pres_end = 0;                           // end of the last mapped byte
  uint16_t preq_end = 0;
};

struct ModuleMapping {
  uint8_t slot = 0;
  uint8_t input_mtu = 0;
  uint8_t output_mtu = 0;
  uint16_t pres_offset = 0;  // in the PRes payload (packed block)
  uint16_t preq_offset = 0;  // in the PReq payload (packed block)
  // From the PDO mapping: every register at fields' offsets instead of the packed block.
  bool by_fields = false;
  FieldOffsets fields;
};

// Where a module's bytes end in the PRes / PReq payload.
[[nodiscard]] constexpr std::size_t pres_end(const ModuleMapping& m) noexcept {
  return m.by_fields ? m.fields.pres_end : m.pres_offset + pres_module_size(m.input_mtu);
}
[[nodiscard]] constexpr std::size_t preq_end(const ModuleMapping& m) noexcept {
  return m.by_fields ? m.fields.preq_end : m.preq_offset + preq_module_size(m.output_mtu);
}
// A module's output bytes in the PReq payload include one of [lo, hi).
[[nodiscard]] bool preq_overlaps(const ModuleMapping& m, std::size_t lo, std::size_t hi) noexcept;

struct NodeImageLayout {
  std::array<ModuleMapping, kMaxModulesPerNode> modules{};
  std::size_t count = 0;
  uint16_t pres_size = 0;  // payload bytes the modules need
  uint16_t preq_size = 0;

  [[nodiscard]] std::span<const ModuleMapping> mappings() const noexcept {
    return {modules.data(), count};
  }
  [[nodiscard]] const ModuleMapping* find(uint8_t slot) const noexcept {
    for (std::size_t i = 0; i < count; ++i)
      if (modules[i].slot == slot) return &modules[i];
    return nullptr;
  }
};

// Layout of one CN, modules sorted by slot, each at its override or its default packed offset;
// pres_size/preq_size = the end of the last block. kInvalidLayout on a duplicate slot, more than
// kMaxModulesPerNode modules or an MTU above kMaxFlatstreamMtu; kModuleBlocksOverlap when two
// blocks share a byte; kModuleBlockOutsidePayload when a block ends past 1490 bytes. `issue`
// (optional) receives the slots involved.
[[nodiscard]] Result<NodeImageLayout> make_layout(std::span<const ModuleSpec> modules,
                                                  LayoutIssue* issue = nullptr) noexcept;

// Writers/readers of one module's bytes. `payload` is the whole PRes/PReq payload; false (and
// nothing written/read) when the module's bytes do not fit in it.
[[nodiscard]] bool write_inputs(std::span<uint8_t> pres_payload, const ModuleMapping& m,
                                const ModuleInputs& in) noexcept;
[[nodiscard]] bool read_inputs(std::span<const uint8_t> pres_payload, const ModuleMapping& m,
                               ModuleInputs& in) noexcept;
[[nodiscard]] bool write_outputs(std::span<uint8_t> preq_payload, const ModuleMapping& m,
                                 const ModuleOutputs& out) noexcept;
[[nodiscard]] bool read_outputs(std::span<const uint8_t> preq_payload, const ModuleMapping& m,
                                ModuleOutputs& out) noexcept;

// NetTime relation: a module's PosTime is the low 32 bits of (SoC RelativeTime µs + offset);
// offset = PowerlinkBusConfig::nettime_offset_us.
[[nodiscard]] constexpr uint64_t net_time_us(uint64_t relative_time_us,
                                             int64_t nettime_offset_us) noexcept {
  return relative_time_us + static_cast<uint64_t>(nettime_offset_us);
}
[[nodiscard]] constexpr uint32_t pos_time_us(uint64_t relative_time_us,
                                             int64_t nettime_offset_us) noexcept {
  return static_cast<uint32_t>(net_time_us(relative_time_us, nettime_offset_us));
}

}  // namespace ds1928::powerlink
