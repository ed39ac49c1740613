#include "flatstream/channel.hpp"

namespace ds1928::flatstream {
namespace {

bool mtu_ok(uint8_t mtu) noexcept {
  return mtu >= kMinMtu && mtu <= kMaxMtu;
}

}  // namespace

std::error_code validate(const MasterConfig& c) noexcept {
  if (!mtu_ok(c.output_mtu) || !mtu_ok(c.input_mtu)) return Errc::invalid_mtu;
  if (static_cast<uint8_t>(c.output_layout) > 3) return Errc::invalid_layout;
  if (c.output_forward < 1 || c.output_forward > kMaxForward) return Errc::invalid_forward;
  if (c.timeout_cycles == 0) return Errc::invalid_timeout;
  return {};
}

std::error_code validate(const ModuleConfig& c) noexcept {
  if (!mtu_ok(c.output_mtu) || !mtu_ok(c.input_mtu)) return Errc::invalid_mtu;
  if (c.flatstream_mode > 3) return Errc::invalid_layout;
  if (c.forward < 1 || c.forward > kMaxForward) return Errc::invalid_forward;
  if (c.timeout_cycles == 0) return Errc::invalid_timeout;
  return {};
}

}  // namespace ds1928::flatstream
