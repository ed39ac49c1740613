// The simulated CN's NetTime anchor: the offset between this host's CLOCK_MONOTONIC and the MN's
// time base, learned from each SoC (arrival instant minus the RelativeTime it carries).
//
// The X20DS1928's NetTime is exact in the MN's time base (datasheet §8: hardware takes the SoC).
// Here a SoC can reach the process milliseconds late (a delayed softirq, a descheduled thread);
// anchoring at each arrival would shift every stamp by that delay and make stamps and positions
// disagree, a fault the module does not have. So the anchor is the earliest arrival seen: it
// follows a sample downwards at once, creeps up by at most kCreepNs per SoC (clock drift between
// hosts is far below that), and takes a jump of kJumpNs or more at once (the MN set its NetTime,
// or sends no RelativeTime that advances; NetTime is then only roughly right). Delays up to
// kJumpNs are ridden through. Pure: no clock, the caller passes the samples.
#pragma once

#include <algorithm>
#include <cstdint>
#include <optional>

namespace ds1928::sim {

class NetTimeAnchor {
 public:
  static constexpr int64_t kCreepNs = 1000;
  static constexpr int64_t kJumpNs = 100'000'000;

  // One SoC: `offset_ns` = its arrival (ns) − its RelativeTime (ns).
  constexpr void sample(int64_t offset_ns) noexcept {
    if (!offset_ || offset_ns < *offset_ || offset_ns - *offset_ >= kJumpNs) {
      offset_ = offset_ns;
    } else {
      offset_ = std::min(*offset_ + kCreepNs, offset_ns);
    }
  }
  // The anchor, or nullopt before the first SoC.
  [[nodiscard]] constexpr std::optional<int64_t> offset() const noexcept { return offset_; }

 private:
  std::optional<int64_t> offset_;
};

}  // namespace ds1928::sim
