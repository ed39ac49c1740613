// Errors of the simulated module's acyclic register access (what a bus controller reports as an
// SDO abort or a CAN-I/O error).
#pragma once

#include <cstdint>
#include <system_error>

namespace ds1928::sim {

enum class SimErrc {
  unknown_register = 1,
  read_only,
  wrong_size,
  out_of_range,
};

[[nodiscard]] const std::error_category& sim_category() noexcept;

[[nodiscard]] inline std::error_code make_error_code(SimErrc e) noexcept {
  return {static_cast<int>(e), sim_category()};
}

// The SDO abort code (core/sdo_abort.hpp) a simulated bus controller answers a register access
// with when the module refused it with `ec`; general error for anything not a SimErrc.
[[nodiscard]] uint32_t sdo_abort_for(std::error_code ec) noexcept;

}  // namespace ds1928::sim

template <>
struct std::is_error_code_enum<ds1928::sim::SimErrc> : std::true_type {};
