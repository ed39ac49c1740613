// Module register → SDO object (index, subindex) on a bus controller, the same scheme behind
// POWERLINK and CAN-I/O (docs/registers.md, column "SDO subindex"): index 0x2000 + slot, the
// subindex of the object dictionary's entry (family members on consecutive subindices). An
// override replaces the entry of a register: the configured (index, subindex) addresses slot 1,
// slot s uses index + (s − 1).
// Pure: no I/O, no allocation after construction.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <utility>

#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {

inline constexpr uint16_t kModuleIndexBase = 0x2000;

struct SdoObject {
  uint16_t index = 0;
  uint8_t subindex = 0;
  friend bool operator==(const SdoObject&, const SdoObject&) = default;
};

struct RegisterAddress {
  uint8_t slot = 1;
  uint16_t reg = 0;
  friend bool operator==(const RegisterAddress&, const RegisterAddress&) = default;
};

// The object dictionary's default subindex of `reg`, and back (nullopt: none).
[[nodiscard]] constexpr std::optional<uint8_t> default_subindex(uint16_t reg) noexcept {
  const RegisterInfo* r = find_register(reg);
  if (!r || r->sdo_subindex == 0) return std::nullopt;
  return static_cast<uint8_t>(r->sdo_subindex + r->member(reg));
}
[[nodiscard]] constexpr std::optional<uint16_t> default_register(uint8_t subindex) noexcept {
  for (const RegisterInfo& r : kObjectDictionary) {
    if (r.view || r.sdo_subindex == 0 || subindex < r.sdo_subindex ||
        subindex >= r.sdo_subindex + r.count)
      continue;
    return static_cast<uint16_t>(r.number + (subindex - r.sdo_subindex) * r.stride);
  }
  return std::nullopt;
}

class SdoMapping {
 public:
  using Overrides = std::map<uint16_t, std::pair<uint16_t, uint8_t>>;
  SdoMapping() = default;
  explicit SdoMapping(const Overrides& overrides);

  // nullopt when the register has neither a default entry nor an override, or slot is 0.
  [[nodiscard]] std::optional<SdoObject> object_for(uint8_t slot, uint16_t reg) const noexcept;
  // Reverse lookup, used by the server side (simulated bus controllers).
  [[nodiscard]] std::optional<RegisterAddress> register_for(SdoObject object) const noexcept;

 private:
  Overrides overrides_;
};

}  // namespace ds1928
