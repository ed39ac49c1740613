// The configured receive strategy (powerlink.rx_wait, rx_spin_us) as raw-link options.
#pragma once

#include <cstdint>

#include "powerlink/powerlink_options.hpp"
#include "powerlink/raw_link.hpp"

namespace ds1928::powerlink {

inline void apply_rx_wait(RxWait wait, uint32_t spin_us, RawLinkOptions& options) noexcept {
  switch (wait) {
    case RxWait::Block:
      options.rx_mode = RxMode::Ring;
      options.ring_spin_ns = static_cast<int64_t>(spin_us) * 1000;
      break;
    case RxWait::Spin:
      options.rx_mode = RxMode::Ring;
      options.ring_spin_ns = -1;
      break;
    case RxWait::BusyPoll:
      options.rx_mode = RxMode::BusyPoll;
      break;
  }
}

[[nodiscard]] constexpr const char* to_string(RxWait w) noexcept {
  switch (w) {
    case RxWait::Block:
      return "block";
    case RxWait::Spin:
      return "spin";
    case RxWait::BusyPoll:
      return "busy_poll";
  }
  return "?";
}

}  // namespace ds1928::powerlink
