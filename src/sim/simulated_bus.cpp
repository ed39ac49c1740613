#include "sim/simulated_bus.hpp"

namespace ds1928::sim {

SimulatedBus::SimulatedBus(std::span<const AxisConfig> axes, const SimulatedBusConfig& simulated) {
  for (std::size_t i = 0; i < axes.size(); ++i) {
    const SimAxisConfig sim = i < simulated.axes.size() ? simulated.axes[i] : SimAxisConfig{};
    auto encoder = load_encoder(sim);
    if (!encoder.description) {
      // Reported by start(); the module gets the built-in encoder meanwhile.
      if (load_error_.empty()) load_error_ = encoder.error;
      encoder.description = default_encoder_description();
    }
    modules_.push_back(std::make_unique<Ds1928Module>(axes[i].function_model, sim,
                                                      std::move(*encoder.description)));
    settings_.push_back(axes[i].module);
  }
}

std::error_code SimulatedBus::start() {
  if (!load_error_.empty()) {
    state_.store(BusState::Error, std::memory_order_release);
    return std::make_error_code(std::errc::invalid_argument);
  }
  // What a master does at boot: power-up defaults, then write the configured settings.
  for (std::size_t i = 0; i < modules_.size(); ++i) {
    modules_[i]->power_up();
    if (auto ec = configure_module(*modules_[i], settings_[i])) {
      state_.store(BusState::Error, std::memory_order_release);
      return ec;
    }
  }
  state_.store(BusState::Operational, std::memory_order_release);
  return {};
}

void SimulatedBus::stop() noexcept {
  state_.store(BusState::Down, std::memory_order_release);
}

ExchangeResult SimulatedBus::exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                                      uint64_t /*cycle_index*/) noexcept {
  // The modules run on the cycle's time (its nominal start on CLOCK_MONOTONIC), not on the clock
  // read here: the bus exchanges at the start of the cycle, and whoever drives the cycles (the
  // engine, or a test stepping time itself) decides how much module time passes.
  const int64_t now_ns = cycle_start_ns;
  // The simulated node's NetTime is that time in µs: the mapping back is exact.
  const uint64_t net_us = static_cast<uint64_t>(now_ns / 1000);

  // Acyclic accesses run between cycles on this thread, which owns the modules.
  registers().serve(*this);

  const std::size_t n = std::min(axes.size(), modules_.size());
  for (std::size_t i = 0; i < n; ++i) {
    modules_[i]->apply_outputs(axes[i].outputs);
    modules_[i]->tick(now_ns, net_us);
    axes[i].inputs = modules_[i]->inputs();
    axes[i].inputs_fresh = true;
    axes[i].rx_time_ns = now_ns;
  }
  ExchangeResult r;
  r.bus_up = true;
  r.net_time = NetTimeRef{net_us, static_cast<int64_t>(net_us) * 1000, true};
  return r;
}

RegisterTarget::Offer SimulatedBus::offer(const RegisterRequest& request) noexcept {
  RegisterResult result;
  result.tag = request.tag;
  if (request.axis >= modules_.size()) {
    result.error = std::make_error_code(std::errc::no_such_device);
  } else if (request.write) {
    result.error = modules_[request.axis]->write_register(request.reg, request.size, request.value);
  } else {
    result.error = modules_[request.axis]->read_register(request.reg, request.size, result.value);
  }
  (void)registers().complete(result);  // held when the results queue is full
  return Offer::kTaken;
}

}  // namespace ds1928::sim
