#include "bus_service.hpp"

namespace ds1928 {

std::unique_ptr<BusService> make_canio_service(const DaemonConfig&, std::string& why_not) {
  why_not = "canio: the CAN-I/O bus driver is not part of this build yet";
  return nullptr;
}

}  // namespace ds1928
