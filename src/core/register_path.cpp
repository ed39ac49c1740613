#include "core/register_path.hpp"

#include <string>

namespace ds1928 {
namespace {

class RegisterPathCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "register_path"; }
  [[nodiscard]] std::string message(int c) const override {
    switch (static_cast<RegisterPathError>(c)) {
      case RegisterPathError::kQueueFull:
        return "register request queue full (" + std::to_string(kRegisterQueueDepth) +
               " requests wait for the bus)";
    }
    return "register path error " + std::to_string(c);
  }
};

}  // namespace

const std::error_category& register_path_category() noexcept {
  static const RegisterPathCategory category;
  return category;
}

}  // namespace ds1928
