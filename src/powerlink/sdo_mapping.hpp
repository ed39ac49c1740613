// Module register → SDO object (index, subindex) on a POWERLINK bus controller.
// Default scheme (docs/powerlink.md §SDO mapping): index 0x2000 + slot; subindex from a fixed
// table for the configuration/control registers and from register ranges for the EnDat
// parameter blocks. PowerlinkBusConfig::sdo_overrides replaces the entry of a register: the
// configured (index, subindex) addresses slot 1, slot s uses index + (s − 1).
// Pure: no I/O, no allocation after construction.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <utility>

#include "core/register_catalogue.hpp"

namespace ds1928::powerlink {

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

// Register sizes come from the register catalogue.
using ds1928::register_size;

class SdoMapping {
 public:
  using Overrides = std::map<uint16_t, std::pair<uint16_t, uint8_t>>;
  SdoMapping() = default;
  explicit SdoMapping(const Overrides& overrides);

  // nullopt when the register has neither a default entry nor an override, or slot is 0.
  [[nodiscard]] std::optional<SdoObject> object_for(uint8_t slot, uint16_t reg) const noexcept;
  // Reverse lookup, used by the server side (simulated bus controller).
  [[nodiscard]] std::optional<RegisterAddress> register_for(SdoObject object) const noexcept;

 private:
  Overrides overrides_;
};

}  // namespace ds1928::powerlink
