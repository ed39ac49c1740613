// A POWERLINK link that records what goes through it: wraps the link the bus driver uses (the
// raw socket) and hands every frame sent (at send) and received (with the link's reception time)
// to a capture Tap. Same thread rules as the wrapped link: send/receive on the cycle thread.
#pragma once

#include <memory>

#include "capture/tap.hpp"
#include "powerlink/link.hpp"

namespace ds1928::capture {

// Frames up to the Ethernet maximum (1514 bytes without FCS) are recorded whole.
inline constexpr std::size_t kMaxEthernetFrame = 1514;

class CapturingLink final : public powerlink::Link {
 public:
  CapturingLink(std::unique_ptr<powerlink::Link> inner, std::string name, std::size_t ring_frames)
      : inner_(std::move(inner)),
        tap_(std::move(name), kLinkTypeEthernet, kMaxEthernetFrame, ring_frames) {}

  [[nodiscard]] std::error_code send(std::span<const uint8_t> frame) noexcept override {
    const std::error_code ec = inner_->send(frame);
    if (!ec) tap_.record(Direction::Outbound, 0, frame);  // an error: the frame did not leave
    return ec;
  }
  [[nodiscard]] powerlink::Received receive(std::span<uint8_t> buffer,
                                            int64_t deadline_ns) noexcept override {
    const powerlink::Received r = inner_->receive(buffer, deadline_ns);
    if (!r.error && r.length != 0)
      tap_.record(Direction::Inbound, r.rx_time_ns, buffer.first(r.length));
    return r;
  }
  [[nodiscard]] bool link_up() const noexcept override { return inner_->link_up(); }
  [[nodiscard]] powerlink::MacAddress mac() const noexcept override { return inner_->mac(); }

  [[nodiscard]] Tap& tap() noexcept { return tap_; }
  [[nodiscard]] powerlink::Link& inner() noexcept { return *inner_; }

 private:
  std::unique_ptr<powerlink::Link> inner_;
  Tap tap_;
};

}  // namespace ds1928::capture
