#include "module_leds.hpp"

#include <string>

#include "module_errors.hpp"

namespace ds1928 {

ModuleLeds module_leds(const BusService& bus, CycleWork& work, const DaemonConfig& config,
                       std::size_t axis) {
  ModuleLeds m;
  const AxisCounters& c = work.counters(axis);
  m.view.node = bus.node_phase(axis);
  m.view.data_arrives = data_arrives(c.last_input_ns.load(std::memory_order_relaxed),
                                     work.last_cycle_ns(), config.cycle.period_us);
  m.state = derive_module_state(m.view);
  m.error_class = module_error_class(m.state, error_words(c));
  return m;
}

void add_module_leds(nlohmann::json& axis, const ModuleLeds& m) {
  axis["module_state"] = std::string(to_string(m.state));
  axis["module_error_class"] = std::string(to_string(m.error_class));
  axis["module"] = {{"r_led", std::string(to_string(r_led(m.state)))},
                    {"e_led", std::string(to_string(e_led(m.error_class)))},
                    {"node_phase", std::string(to_string(m.view.node))},
                    {"data_arrives", m.view.data_arrives}};
}

void append_module_metrics(metrics::Exposition& out, const BusService& bus, CycleWork& work,
                           const DaemonConfig& config) {
  constexpr ModuleState kStates[] = {ModuleState::Off, ModuleState::Reset, ModuleState::Boot,
                                     ModuleState::PreOp, ModuleState::Run};
  constexpr ModuleErrorClass kClasses[] = {ModuleErrorClass::None,   ModuleErrorClass::Reset,
                                           ModuleErrorClass::Supply, ModuleErrorClass::Io,
                                           ModuleErrorClass::System, ModuleErrorClass::IoAndSystem};
  std::vector<ModuleLeds> leds;
  leds.reserve(config.axes.size());
  for (std::size_t i = 0; i < config.axes.size(); ++i)
    leds.push_back(module_leds(bus, work, config, i));
  out.family("ds1928_axis_module_state", metrics::Type::Gauge,
             "1 for the state the module's r-LED would show (off, reset, boot, preop, run), from "
             "what the bus shows of its node and whether its data arrives.");
  for (std::size_t i = 0; i < leds.size(); ++i)
    for (const ModuleState s : kStates)
      out.sample(
          {{"axis", std::to_string(i)}, {"name", config.axes[i].name}, {"state", to_string(s)}},
          uint64_t{leds[i].state == s ? 1u : 0u});
  out.family("ds1928_axis_module_error_class", metrics::Type::Gauge,
             "1 for the error class the module's e-LED would flash (none, reset, supply, io, "
             "system, io_and_system), from its ErrorInfo bits.");
  for (std::size_t i = 0; i < leds.size(); ++i)
    for (const ModuleErrorClass e : kClasses)
      out.sample(
          {{"axis", std::to_string(i)}, {"name", config.axes[i].name}, {"class", to_string(e)}},
          uint64_t{leds[i].error_class == e ? 1u : 0u});
}

}  // namespace ds1928
