// A CAN port that records what goes through it: wraps a CanPort (SocketCAN or the virtual bus)
// and hands every frame sent (at send) and received — data, remote and error frames, with the
// port's reception time — to a capture Tap in SocketCAN form. Same thread rules as the wrapped
// port: send/receive on the port's one thread, the rest passed through.
#pragma once

#include <memory>

#include "can/can_port.hpp"
#include "capture/can_record.hpp"
#include "capture/tap.hpp"

namespace ds1928::capture {

class CapturingCanPort final : public canio::CanPort {
 public:
  // `name`: the interface name in the capture (e.g. "can0 cycle").
  CapturingCanPort(std::unique_ptr<canio::CanPort> inner, std::string name, std::size_t ring_frames)
      : inner_(std::move(inner)),
        tap_(std::move(name), kLinkTypeCanSocketCan, kSocketCanFrameSize, ring_frames) {}

  canio::SendResult send(const canio::CanFrame& frame) noexcept override {
    const canio::SendResult r = inner_->send(frame);
    if (r.sent()) tap_.record(Direction::Outbound, 0, socketcan_bytes(frame));
    return r;
  }
  canio::ReceiveResult receive(std::span<canio::CanFrame> frames,
                               int64_t deadline_ns) noexcept override {
    const canio::ReceiveResult r = inner_->receive(frames, deadline_ns);
    for (std::size_t i = 0; i < r.count && i < frames.size(); ++i)
      tap_.record(Direction::Inbound, frames[i].rx_time_ns, socketcan_bytes(frames[i]));
    return r;
  }
  [[nodiscard]] canio::CanState state() const noexcept override { return inner_->state(); }
  [[nodiscard]] canio::CanPortCounters counters() const noexcept override {
    return inner_->counters();
  }
  [[nodiscard]] std::error_code set_filters(
      std::span<const canio::CanIdFilter> ids) noexcept override {
    return inner_->set_filters(ids);
  }
  [[nodiscard]] std::error_code set_error_mask(uint32_t classes) noexcept override {
    return inner_->set_error_mask(classes);
  }
  [[nodiscard]] Result<canio::CanInterfaceInfo> query_interface() noexcept override {
    return inner_->query_interface();
  }
  [[nodiscard]] std::string_view name() const noexcept override { return inner_->name(); }

  [[nodiscard]] Tap& tap() noexcept { return tap_; }

 private:
  std::unique_ptr<canio::CanPort> inner_;
  Tap tap_;
};

}  // namespace ds1928::capture
