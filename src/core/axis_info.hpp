// The additional-information channels of one axis as the daemon publishes them (datasheet
// §11.8.3): the last value EnDatInfo0N carried while its EnDatInfoOK bit was set, whether the
// last read had that bit, and when the value was read. Pure; the cycle updates it from fresh
// inputs, a bus that reads the channels acyclically from its register results.
#pragma once

#include <array>
#include <cstdint>
#include <limits>

#include "x20ds1928/info_channels.hpp"

namespace ds1928 {

struct AxisInfo {
  std::array<int32_t, kInfoChannels> value{};    // EnDatInfo0N of the last valid read
  std::array<int64_t, kInfoChannels> read_ns{};  // when that read was taken (0: never)
  uint8_t valid = 0;       // bit n: channel n's last read had EnDatInfoOK bit n set
  uint8_t configured = 0;  // bit n: channel n is configured (axes[].info)
  uint8_t is_signed = 0;   // bit n: EnDatInfo0N reads as INT (sign-extended), else UINT
};

// One read of all four channels at `now_ns` (fresh inputs, or one acyclic read of EnDatInfoOK and
// EnDatInfo01..04): a configured channel whose OK bit is set takes the word; one whose bit is
// clear keeps its last value (its age grows) and loses its valid bit.
constexpr void update_axis_info(AxisInfo& info, uint8_t info_ok,
                                const std::array<uint16_t, kInfoChannels>& words,
                                int64_t now_ns) noexcept {
  info.valid = static_cast<uint8_t>(info_ok & info.configured);
  for (std::size_t n = 0; n < kInfoChannels; ++n) {
    if ((info.valid & (1u << n)) == 0) continue;
    info.value[n] = (info.is_signed & (1u << n)) != 0 ? int32_t{static_cast<int16_t>(words[n])}
                                                      : int32_t{words[n]};
    info.read_ns[n] = now_ns;
  }
}

// A channel's age at `now_ns` in µs (saturating), or UINT32_MAX when it never had a valid read.
[[nodiscard]] constexpr uint32_t info_age_us(const AxisInfo& info, std::size_t n,
                                             int64_t now_ns) noexcept {
  constexpr uint32_t kNever = std::numeric_limits<uint32_t>::max();
  if (n >= kInfoChannels || info.read_ns[n] == 0) return kNever;
  const int64_t us = (now_ns - info.read_ns[n]) / 1000;
  if (us <= 0) return 0;
  return us >= int64_t{kNever} ? kNever - 1 : static_cast<uint32_t>(us);
}

}  // namespace ds1928
