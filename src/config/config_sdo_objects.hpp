// The register → SDO object lists of both buses (powerlink.sdo_overrides,
// canio.acyclic.sdo_objects): one reader, so both accept and refuse the same entries. Internal to
// src/config.
#pragma once

#include <cstdint>
#include <map>
#include <string_view>
#include <utility>

#include "config/config_reader.hpp"

namespace ds1928::config_detail {

// Reads the list `key` of `s`: entries {register, index, subindex = 0}. The register must be one
// of the object dictionary's (docs/registers.md) and appear once; index 1..0xFFFF. Each entry that
// is whole lands in `out` (register → (index, subindex)); each wrong one gets an error naming it.
void parse_sdo_objects(Section& s, std::string_view key,
                       std::map<uint16_t, std::pair<uint16_t, uint8_t>>& out);

}  // namespace ds1928::config_detail
