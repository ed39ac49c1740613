// The in-process bus: the daemon's default when no hardware is configured. It owns one simulated
// X20DS1928 per axis and offers exactly the per-cycle interface of the real buses. Its modules'
// clock is the cycle's start time passed to exchange(): deterministic under a test's own steps.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "core/axis_config.hpp"
#include "core/bus.hpp"
#include "sim/ds1928_module.hpp"
#include "sim/sim_options.hpp"

namespace ds1928::sim {

class SimulatedBus final : public BusDriver, private RegisterTarget {
 public:
  // One simulated X20DS1928 per axis; simulated.axes[i] describes axes[i] (defaults for the
  // rest).
  SimulatedBus(std::span<const AxisConfig> axes, const SimulatedBusConfig& simulated);

  [[nodiscard]] std::string_view name() const noexcept override { return "simulated"; }
  [[nodiscard]] std::error_code start() override;
  void stop() noexcept override;
  ExchangeResult exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                          uint64_t cycle_index) noexcept override;
  [[nodiscard]] BusState state() const noexcept override {
    return state_.load(std::memory_order_acquire);
  }

  // Test hooks: reach a module between cycles (only while the cycle thread is not running).
  [[nodiscard]] Ds1928Module& module(std::size_t axis) { return *modules_.at(axis); }
  // Why start() failed to set up an encoder ("file:line:column: key: what"), or empty.
  [[nodiscard]] const std::string& load_error() const noexcept { return load_error_; }

 private:
  // Register requests run between cycles on the cycle thread, which owns the modules.
  Offer offer(const RegisterRequest& request) noexcept override;

  std::vector<std::unique_ptr<Ds1928Module>> modules_;
  std::vector<ModuleSettings> settings_;
  std::atomic<BusState> state_{BusState::Down};
  std::string load_error_;
};

}  // namespace ds1928::sim
