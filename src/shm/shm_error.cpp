#include "shm/shm_error.hpp"

#include <string>

namespace ds1928::shm {
namespace {

class ShmCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "ds1928.shm"; }
  std::string message(int value) const override {
    switch (static_cast<ShmError>(value)) {
      case ShmError::kInvalidName:
        return "shared memory name must be '/' followed by up to 250 characters without '/'";
      case ShmError::kNoAxes:
        return "no axes to publish";
      case ShmError::kTooManyAxes:
        return "too many axes for the shared memory layout";
      case ShmError::kUnknownGroup:
        return "shared memory group does not exist";
      case ShmError::kNameInUse:
        return "another running daemon publishes under this name";
      case ShmError::kNotRegularFile:
        return "a symbolic link or non-regular file holds the name in /dev/shm; refusing to "
               "follow or replace it (remove it if it is not meant to be there)";
      case ShmError::kForeignOwner:
        return "a file of another user holds the name in /dev/shm; refusing to adopt or remove "
               "it (remove it if it is not meant to be there)";
    }
    return "unknown shared memory error";
  }
};

}  // namespace

const std::error_category& shm_category() noexcept {
  static const ShmCategory category;
  return category;
}

}  // namespace ds1928::shm
