// The daemon's side of the in-process simulated bus: nothing beyond the common status (and no
// metrics of its own), and the encoder file's error when the bus cannot start. Same shape as every
// bus kind: <kind>_service.hpp/.cpp (+ <kind>_metrics.cpp when it has metric families).
#pragma once

#include "bus_service.hpp"
#include "sim/simulated_bus.hpp"

namespace ds1928 {

class SimulatedService final : public BusService {
 public:
  explicit SimulatedService(const DaemonConfig& config) : bus_(config.axes, config.simulated) {}
  [[nodiscard]] BusDriver& driver() noexcept override { return bus_; }
  [[nodiscard]] std::string start_detail() const override { return bus_.load_error(); }

 private:
  sim::SimulatedBus bus_;
};

}  // namespace ds1928
