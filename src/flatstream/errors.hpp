// Flatstream results as std::error_code (own category "flatstream"): rejected submits, invalid
// configuration, and why a message was reported failed.
#pragma once

#include <system_error>

namespace ds1928::flatstream {

enum class Errc : int {
  ok = 0,
  // submit()
  message_too_long = 1,  // longer than kMaxMessageSize
  queue_full,            // kQueueDepth messages already queued or with an untaken outcome
  // configuration
  invalid_mtu,      // MTU outside 2..27
  invalid_forward,  // Forward outside 1..7
  invalid_layout,   // FlatstreamMode with reserved bits set
  invalid_timeout,  // timeout of 0 cycles
  // send outcomes other than delivered
  timeout,           // a sequence of the message stayed unacknowledged past timeout_cycles
  unconfirmed,       // channel resynchronised after the message's last sequence was sent but before
                     // it was acknowledged: the peer got it at most once (maybe not at all)
  resend_limit,      // interrupted by resynchronisation more often than kMaxResends; never complete
  not_synchronised,  // the direction could not be synchronised within timeout_cycles
  channel_reset,     // reset() while the message was queued or in flight; never completed
};

[[nodiscard]] const std::error_category& flatstream_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(Errc e) noexcept {
  return {static_cast<int>(e), flatstream_category()};
}

}  // namespace ds1928::flatstream

template <>
struct std::is_error_code_enum<ds1928::flatstream::Errc> : std::true_type {};
