// The wire as the Managing Node sees it: whole Ethernet frames out and in. The raw-socket link
// (raw_link.hpp) implements it on AF_PACKET; tests implement it in memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <system_error>

#include "powerlink/frames.hpp"

namespace ds1928::powerlink {

struct Received {
  std::size_t length = 0;  // 0: nothing arrived before the deadline
  int64_t rx_time_ns = 0;  // CLOCK_MONOTONIC reception time (0 when unknown)
  std::error_code error;   // link failure (not a timeout)
};

class Link {
 public:
  virtual ~Link() = default;

  // Sends one complete frame (already padded to 60 bytes). Never blocks for long; an error means
  // the frame did not leave.
  [[nodiscard]] virtual std::error_code send(std::span<const uint8_t> frame) noexcept = 0;

  // Polls for the next received POWERLINK frame until `deadline_ns` (CLOCK_MONOTONIC). A deadline
  // in the past makes it a single non-blocking poll. Frames the link sent itself are not returned.
  [[nodiscard]] virtual Received receive(std::span<uint8_t> buffer,
                                         int64_t deadline_ns) noexcept = 0;

  // Carrier / interface state; false when the link was lost.
  [[nodiscard]] virtual bool link_up() const noexcept = 0;

  // Source MAC for frames sent on this link.
  [[nodiscard]] virtual MacAddress mac() const noexcept = 0;
};

}  // namespace ds1928::powerlink
