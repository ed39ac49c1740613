// The module's error bits for ds1928ctl (x20ds1928/error_bits.hpp): every set bit by name with
// its class and remedy, from the daemon's status JSON or from a shared-memory record's words.
#pragma once

#include <nlohmann/json.hpp>

#include "x20ds1928/error_bits.hpp"

namespace ds1928::ctl {

// [{register, bit, name, class, meaning, remedy}, ...] of the set bits (no per-axis effect: a
// shared-memory reader does not know axes[].invalidate_on).
[[nodiscard]] nlohmann::json error_bits_json(const ErrorWords& words);
// One indented line per entry of such a list: "name (class[, effect]): meaning — remedy".
void print_error_bits(const nlohmann::json& bits);

}  // namespace ds1928::ctl
