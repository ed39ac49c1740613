#include "can/errors.hpp"

#include <string>

namespace ds1928::canio {
namespace {

class CanCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "canio"; }
  std::string message(int ev) const override {
    switch (static_cast<CanError>(ev)) {
      case CanError::kNotAnErrorFrame:
        return "not an error frame";
      case CanError::kErrorFrameLength:
        return "error frame with a data length other than 8";
      case CanError::kUnknownErrorClass:
        return "error frame with an unknown error class";
      case CanError::kInvalidFrame:
        return "invalid CAN frame (identifier out of range, more than 8 data bytes, or error flag)";
      case CanError::kNoCanSupport:
        return "this kernel has no CAN support (socket(AF_CAN) failed: load the can and can-raw "
               "modules, or use the virtual bus)";
      case CanError::kNoSuchInterface:
        return "no such CAN interface";
      case CanError::kNotCanInterface:
        return "the interface is not a CAN interface";
      case CanError::kInterfaceDown:
        return "the CAN interface is down";
      case CanError::kBusOff:
        return "the CAN controller is bus-off";
      case CanError::kBitrateMismatch:
        return "the CAN interface's bit rate differs from the configuration";
      case CanError::kTooManyFilters:
        return "more CAN identifiers than the port's filter table holds";
      case CanError::kInterfaceNameInvalid:
        return "CAN interface name empty or too long";
      case CanError::kNetlink:
        return "rtnetlink query of the CAN interface failed";
      case CanError::kNotOpen:
        return "CAN port not open";
      case CanError::kVirtualBusMismatch:
        return "a virtual CAN bus of that name exists with another layout";
    }
    return "unknown CAN-I/O error " + std::to_string(ev);
  }
};

}  // namespace

const std::error_category& can_category() noexcept {
  static const CanCategory category;
  return category;
}

}  // namespace ds1928::canio
