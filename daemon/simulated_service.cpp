#include "simulated_service.hpp"

namespace ds1928 {

std::unique_ptr<BusService> make_simulated_service(const DaemonConfig& config, std::string&) {
  return std::make_unique<SimulatedService>(config);
}

}  // namespace ds1928
