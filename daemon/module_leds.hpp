// Per axis the module's state and error class as its r- and e-LED would show them
// (x20ds1928/module_state.hpp), from what the bus shows of its node (BusService::node_phase), the
// arrival of its inputs (AxisCounters::last_input_ns) and its ErrorInfo: for `status`,
// `topology` and the metrics. Normal thread.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>

#include "bus_service.hpp"
#include "config/config.hpp"
#include "cycle_work.hpp"
#include "metrics/exposition.hpp"
#include "x20ds1928/module_state.hpp"

namespace ds1928 {

struct ModuleLeds {
  ModuleView view;
  ModuleState state = ModuleState::Off;
  ModuleErrorClass error_class = ModuleErrorClass::None;
};

[[nodiscard]] ModuleLeds module_leds(const BusService& bus, CycleWork& work,
                                     const DaemonConfig& config, std::size_t axis);
// Adds "module_state", "module_error_class" and "module": {"r_led", "e_led", "node_phase",
// "data_arrives"} to an axis' object.
void add_module_leds(nlohmann::json& axis, const ModuleLeds& leds);
// ds1928_axis_module_state{state} and ds1928_axis_module_error_class{class}: one sample per
// value, 1 for the axis' current one (an OpenMetrics state set written as gauges).
void append_module_metrics(metrics::Exposition& out, const BusService& bus, CycleWork& work,
                           const DaemonConfig& config);

}  // namespace ds1928
