#include "sim/sim_error.hpp"

#include <string>

#include "core/sdo_abort.hpp"

namespace ds1928::sim {

namespace {
class SimCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "ds1928.module-register"; }
  std::string message(int ev) const override {
    switch (static_cast<SimErrc>(ev)) {
      case SimErrc::unknown_register:
        return "no such register in this function model";
      case SimErrc::read_only:
        return "register is read-only";
      case SimErrc::wrong_size:
        return "access size does not match the register's type";
      case SimErrc::out_of_range:
        return "value out of the register's range";
    }
    return "unknown module register error";
  }
};
}  // namespace

const std::error_category& sim_category() noexcept {
  static const SimCategory category;
  return category;
}

uint32_t sdo_abort_for(std::error_code ec) noexcept {
  if (ec == SimErrc::unknown_register) return sdo_abort::kNoObject;
  if (ec == SimErrc::read_only) return sdo_abort::kReadOnly;
  if (ec == SimErrc::wrong_size) return sdo_abort::kTypeLength;
  if (ec == SimErrc::out_of_range) return sdo_abort::kOutOfRange;
  return sdo_abort::kGeneral;
}

}  // namespace ds1928::sim
