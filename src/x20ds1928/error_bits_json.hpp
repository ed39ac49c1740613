// The set error bits as JSON (x20ds1928/error_bits.hpp): what the daemon's status and
// `ds1928ctl position` print for each set bit. Normal thread only (allocates).
#pragma once

#include <nlohmann/json.hpp>

#include "x20ds1928/error_bits.hpp"

namespace ds1928 {

// [{register, bit, name, class, meaning, remedy}, ...] of the set bits, lowest first; a reserved
// bit has class "reserved" and no meaning. Without a policy there is no "effect": a
// shared-memory reader does not know the axis' axes[].invalidate_on.
[[nodiscard]] nlohmann::json error_bits_json(const ErrorWords& words);
// The same with each bit's effect on this axis: "module_error", "hold" or "flag".
[[nodiscard]] nlohmann::json error_bits_json(const ErrorWords& words, const ErrorPolicy& policy);

}  // namespace ds1928
