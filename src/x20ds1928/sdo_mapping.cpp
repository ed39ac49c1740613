#include "x20ds1928/sdo_mapping.hpp"

namespace ds1928 {

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

}  // namespace ds1928
