// The daemon's side of the in-process simulated bus: nothing beyond the common status, and the
// encoder file's error when the bus cannot start.
#include "bus_service.hpp"
#include "sim/simulated_bus.hpp"

namespace ds1928 {
namespace {

class SimulatedService final : public BusService {
 public:
  explicit SimulatedService(const DaemonConfig& config) : bus_(config.axes, config.simulated) {}
  [[nodiscard]] BusDriver& driver() noexcept override { return bus_; }
  [[nodiscard]] std::string start_detail() const override { return bus_.load_error(); }

 private:
  sim::SimulatedBus bus_;
};

}  // namespace

std::unique_ptr<BusService> make_simulated_service(const DaemonConfig& config, std::string&) {
  return std::make_unique<SimulatedService>(config);
}

}  // namespace ds1928
