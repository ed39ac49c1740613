#include "flatstream/errors.hpp"

#include <string>

namespace ds1928::flatstream {
namespace {

class Category final : public std::error_category {
 public:
  const char* name() const noexcept override { return "flatstream"; }
  std::string message(int ev) const override {
    switch (static_cast<Errc>(ev)) {
      case Errc::ok:
        return "ok";
      case Errc::message_too_long:
        return "message longer than the Flatstream limit of 512 bytes";
      case Errc::queue_full:
        return "Flatstream send queue full";
      case Errc::invalid_mtu:
        return "Flatstream MTU outside 2..27 bytes";
      case Errc::invalid_forward:
        return "Flatstream Forward outside 1..7";
      case Errc::invalid_layout:
        return "FlatstreamMode has reserved bits set (only bits 0-1 exist)";
      case Errc::invalid_timeout:
        return "Flatstream timeout must be at least 1 cycle";
      case Errc::timeout:
        return "Flatstream sequence not acknowledged within the timeout";
      case Errc::unconfirmed:
        return "Flatstream channel resynchronised before the message was acknowledged "
               "(received at most once)";
      case Errc::resend_limit:
        return "Flatstream message interrupted by resynchronisation too often";
      case Errc::not_synchronised:
        return "Flatstream direction could not be synchronised";
      case Errc::channel_reset:
        return "Flatstream channel reset before the message was sent";
    }
    return "unknown flatstream error " + std::to_string(ev);
  }
};

}  // namespace

const std::error_category& flatstream_category() noexcept {
  static const Category category;
  return category;
}

}  // namespace ds1928::flatstream
