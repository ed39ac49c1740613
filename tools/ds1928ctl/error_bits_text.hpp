// The module's error bits for ds1928ctl (x20ds1928/error_bits.hpp): every set bit by name with
// its class and remedy, from the daemon's status JSON or from a shared-memory record's words
// (x20ds1928/error_bits_json.hpp builds the list for both).
#pragma once

#include <nlohmann/json.hpp>

#include "x20ds1928/error_bits_json.hpp"

namespace ds1928::ctl {

// One indented line per entry of an error_bits_json() list: "name (class[, effect]): meaning —
// remedy".
void print_error_bits(const nlohmann::json& bits);

}  // namespace ds1928::ctl
