// Process-data image of one Controlled Node: where each X20DS1928 (function model 0) sits in the
// PRes and PReq payloads. Shared by the Managing Node and the simulated CN, so both ends agree.
// Default layout (docs/powerlink.md §Process image): modules in ascending slot order, packed,
// starting at payload offset 0.
//   PRes per module: PositionHW u32 | PositionLW u32 | PosTime u32 | PosCycle i8 |
//                    SDCLifeCount i8 | ErrorInfo u8 | InputSequence u8 | RxBytes[InputMTU]
//   PReq per module: OutputSequence u8 | TxBytes[OutputMTU] | AckErrorInfo u8
// Pure: no I/O, no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/module_image.hpp"
#include "powerlink/errors.hpp"

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
  uint8_t slot = 1;
  uint8_t input_mtu = 7;
  uint8_t output_mtu = 7;
};

struct ModuleMapping {
  uint8_t slot = 0;
  uint8_t input_mtu = 0;
  uint8_t output_mtu = 0;
  uint16_t pres_offset = 0;  // in the PRes payload
  uint16_t preq_offset = 0;  // in the PReq payload
};

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

// Default packed layout, modules sorted by slot. kInvalidLayout on a duplicate slot, more than
// kMaxModulesPerNode modules, an MTU above kMaxFlatstreamMtu or a payload above 1490 bytes.
[[nodiscard]] Result<NodeImageLayout> make_layout(std::span<const ModuleSpec> modules) noexcept;

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
