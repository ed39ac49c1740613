// The POWERLINK cycle budget of a configuration (docs/powerlink.md §Cycle budget): its nominal
// and worst-case figures from the pure budget (powerlink/cycle_budget.hpp), the nodes' frames
// taken from the axes, the PResMN grown to the chained nodes' outputs. The configuration refuses
// a nominal cycle that does not fit the period; the daemon warns about a worst case that does not
// (log at start, status, metric).
#pragma once

#include <cstdint>
#include <string>

#include "config/config.hpp"
#include "powerlink/cycle_budget.hpp"

namespace ds1928 {

struct PowerlinkCycleBudget {
  uint32_t period_us = 0;
  powerlink::CycleBudget nominal;
  powerlink::CycleBudget worst;
  [[nodiscard]] bool nominal_fits() const noexcept { return nominal.total_us() <= period_us; }
  [[nodiscard]] bool worst_fits() const noexcept { return worst.total_us() <= period_us; }
};

[[nodiscard]] PowerlinkCycleBudget powerlink_cycle_budget(const DaemonConfig& c);

// "SoC 6.7, WaitSoCPReq 0.0, PRC slot of 0 node(s) 0.0, 4 PReq/PRes with their PRes latencies
// 61.8, SoA 6.7 + ASnd latency 2.0 + ASnd of AsyncMTU 300 27.0": each term of `b` with its
// figure in µs.
[[nodiscard]] std::string budget_terms(const powerlink::CycleBudget& b, uint16_t async_mtu);

// The warning the daemon logs at start when the worst case does not fit (empty when it does).
[[nodiscard]] std::string worst_case_warning(const PowerlinkCycleBudget& b, uint16_t async_mtu);

}  // namespace ds1928
