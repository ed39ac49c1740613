#include "powerlink/sdo_mapping.hpp"

#include <array>

#include "core/module_image.hpp"

namespace ds1928::powerlink {
namespace {

struct TableEntry {
  uint16_t reg;
  uint8_t subindex;
};

// Configuration and control registers: subindex 0x01..0x1A (docs/powerlink.md, SDO mapping).
constexpr std::array<TableEntry, 26> kTable{{
    {reg::kEnDatMode, 0x01},
    {reg::kSystemCyclePrescaler, 0x02},
    {reg::kSlframeGenId, 0x03},
    {reg::kErrorEnable, 0x04},
    {reg::kSinCosEnable, 0x05},
    {reg::kSinCosRefSource, 0x06},
    {reg::kSinCosVssMin, 0x07},
    {reg::kSinCosVssMax, 0x08},
    {reg::kSinCosQuitTime, 0x09},
    {reg::kOutputMtu, 0x0A},
    {reg::kInputMtu, 0x0B},
    {reg::kFlatstreamMode, 0x0C},
    {reg::kForward, 0x0D},
    {reg::kForwardDelay, 0x0E},
    {reg::kEnDatAck, 0x0F},
    {261, 0x10},   // ErrorInfo
    {325, 0x11},   // AckErrorInfo
    {4868, 0x12},  // EnDatInfoCmd01..04 (4860 + N·8)
    {4876, 0x13},
    {4884, 0x14},
    {4892, 0x15},
    {4935, 0x16},  // EnDatInfoOK
    {4994, 0x17},  // EnDatInfo01..04 (4978 + N·16)
    {5010, 0x18},
    {5026, 0x19},
    {5042, 0x1A},
}};

// Register ranges of UINT words: OperatingStatus/ParamManuf 4352..4399, OperatingParam
// 4400..4415, ParamManufEnDat22 4416..4479.
struct Range {
  uint16_t first;
  uint16_t count;
  uint8_t first_subindex;
};
constexpr std::array<Range, 3> kRanges{{{4352, 48, 0x20}, {4400, 16, 0x50}, {4416, 64, 0x60}}};

std::optional<uint8_t> default_subindex(uint16_t reg) noexcept {
  for (const TableEntry& e : kTable)
    if (e.reg == reg) return e.subindex;
  for (const Range& r : kRanges)
    if (reg >= r.first && reg < r.first + r.count)
      return static_cast<uint8_t>(r.first_subindex + (reg - r.first));
  return std::nullopt;
}

std::optional<uint16_t> default_register(uint8_t subindex) noexcept {
  for (const TableEntry& e : kTable)
    if (e.subindex == subindex) return e.reg;
  for (const Range& r : kRanges)
    if (subindex >= r.first_subindex && subindex < r.first_subindex + r.count)
      return static_cast<uint16_t>(r.first + (subindex - r.first_subindex));
  return std::nullopt;
}

}  // namespace

SdoMapping::SdoMapping(const Overrides& overrides) : overrides_(overrides) {}

std::optional<SdoObject> SdoMapping::object_for(uint8_t slot, uint16_t reg) const noexcept {
  if (slot == 0) return std::nullopt;
  if (auto it = overrides_.find(reg); it != overrides_.end())
    return SdoObject{static_cast<uint16_t>(it->second.first + (slot - 1)), it->second.second};
  auto sub = default_subindex(reg);
  if (!sub) return std::nullopt;
  return SdoObject{static_cast<uint16_t>(kModuleIndexBase + slot), *sub};
}

std::optional<RegisterAddress> SdoMapping::register_for(SdoObject object) const noexcept {
  // Overrides win over the default table, as in object_for().
  for (const auto& [reg, target] : overrides_) {
    if (object.subindex != target.second || object.index < target.first) continue;
    const unsigned slot = object.index - target.first + 1U;
    if (slot <= 0xFF && slot <= 64) return RegisterAddress{static_cast<uint8_t>(slot), reg};
  }
  if (object.index <= kModuleIndexBase || object.index > kModuleIndexBase + 0xFF)
    return std::nullopt;
  auto reg = default_register(object.subindex);
  if (!reg || overrides_.count(*reg)) return std::nullopt;
  return RegisterAddress{static_cast<uint8_t>(object.index - kModuleIndexBase), *reg};
}

}  // namespace ds1928::powerlink
