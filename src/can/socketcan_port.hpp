// The CAN port on the Linux kernel's CAN stack: one CAN_RAW socket bound to the configured
// interface.
//  - CAN_RAW_FILTER: exactly the identifiers in use (set_filters), so the cycle thread never
//    wakes for foreign traffic.
//  - CAN_RAW_ERR_FILTER: bus-off, controller, protocol, TX timeout, ACK, transceiver, restarted
//    (kDefaultErrorMask); error frames are decoded and move state().
//  - SO_TIMESTAMPING (software RX stamps), falling back to SO_TIMESTAMPNS: the kernel's
//    reception time arrives as a cmsg of the same recvmmsg (no SIOCGSTAMP syscall per frame) and
//    is moved from CLOCK_REALTIME to CLOCK_MONOTONIC.
//  - SO_RXQ_OVFL: the kernel's count of frames dropped on a full socket queue (rx_kernel_drops).
//  - send(MSG_DONTWAIT): ENOBUFS / EAGAIN (full TX queue) counted and reported, never retried;
//    ENETDOWN reported as InterfaceDown.
// Interface state, bit rate and restart-ms come from rtnetlink (can_netlink.hpp).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <system_error>

#include "can/can_error_frame.hpp"
#include "can/can_netlink.hpp"
#include "can/can_port.hpp"
#include "core/unique_fd.hpp"

namespace ds1928::canio {

struct SocketCanOptions {
  std::string interface = "can0";
  uint32_t expected_bitrate = 0;  // checked against IFLA_CAN_BITTIMING at open (0: not checked)
  bool require_up = true;         // an interface that is down is an open() error
  uint32_t error_mask = kDefaultErrorMask;
  int receive_buffer_bytes = 0;  // SO_RCVBUF (0: kernel default)
  // Our own frames come back (MSG_CONFIRM) with their transmission stamp. Off: the driver has no
  // use for it yet.
  bool receive_own = false;
};

struct SocketCanOpen {
  std::unique_ptr<class SocketCanPort> port;  // set on success
  std::error_code error;                      // CanError or errno
  std::string message;                        // for the user, names the interface and the fix
};

// The socket's settings as read back from the kernel (getsockopt), for tests and `status`.
struct SocketCanSettings {
  uint32_t error_mask = 0;
  std::size_t filter_count = 0;
  bool timestamping = false;  // SO_TIMESTAMPING (else SO_TIMESTAMPNS)
  bool rxq_overflow = false;  // SO_RXQ_OVFL
};

class SocketCanPort final : public CanPort {
 public:
  // Checks the interface over netlink (exists, is CAN, up, bit rate), opens and binds the
  // socket. Errors: kNoCanSupport ("this kernel has no AF_CAN ..."), kNoSuchInterface,
  // kNotCanInterface, kInterfaceDown, kBitrateMismatch, or the errno of the failing call.
  [[nodiscard]] static SocketCanOpen open(const SocketCanOptions& options);

  ~SocketCanPort() override;
  SocketCanPort(const SocketCanPort&) = delete;
  SocketCanPort& operator=(const SocketCanPort&) = delete;

  SendResult send(const CanFrame& frame) noexcept override;
  ReceiveResult receive(std::span<CanFrame> frames, int64_t deadline_ns) noexcept override;
  [[nodiscard]] CanState state() const noexcept override;
  [[nodiscard]] CanPortCounters counters() const noexcept override;
  [[nodiscard]] std::error_code set_filters(std::span<const CanIdFilter> ids) noexcept override;
  [[nodiscard]] std::error_code set_error_mask(uint32_t classes) noexcept override;
  [[nodiscard]] Result<CanInterfaceInfo> query_interface() noexcept override;
  [[nodiscard]] std::string_view name() const noexcept override { return options_.interface; }

  [[nodiscard]] Result<SocketCanSettings> read_settings() const noexcept;
  [[nodiscard]] int fd() const noexcept { return fd_.get(); }

 private:
  struct Impl;
  SocketCanPort(SocketCanOptions options, UniqueFd fd);

  SocketCanOptions options_;
  UniqueFd fd_;
  std::unique_ptr<Impl> impl_;  // receive buffers and counters, allocated once at open
};

// True when this kernel can make CAN_RAW sockets (false with the errno, e.g. EAFNOSUPPORT).
[[nodiscard]] std::error_code probe_af_can() noexcept;

}  // namespace ds1928::canio
