// POWERLINK on a Linux Ethernet port: an AF_PACKET raw socket bound to one interface and the
// POWERLINK EtherType, with the POWERLINK multicast memberships and PACKET_QDISC_BYPASS.
// Only moves bytes; the protocol lives in the MN / CN cores.
//
// Receive strategies (docs/realtime.md §POWERLINK receive strategy has the measurements):
//  - Ring:     TPACKET_V2 RX ring, its frame's status word polled for at most `ring_spin_ns`,
//              then ppoll() until the deadline (the kernel wakes the thread when a frame lands).
//              ring_spin_ns < 0 spins to the deadline: no syscall, but a SCHED_FIFO thread that
//              spins keeps every lower-priority thread of its CPU — a software CN's responder,
//              ksoftirqd — from running until it gives up.
//  - BusyPoll: recv(MSG_DONTWAIT) in a loop until the deadline.
//  - Blocking: ppoll() until the deadline, then recv (no ring).
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <system_error>

#include "powerlink/link.hpp"

namespace ds1928::powerlink {

enum class RxMode : uint8_t { Ring = 0, BusyPoll = 1, Blocking = 2 };

[[nodiscard]] constexpr const char* to_string(RxMode m) noexcept {
  switch (m) {
    case RxMode::Ring:
      return "ring";
    case RxMode::BusyPoll:
      return "busy-poll";
    case RxMode::Blocking:
      return "blocking";
  }
  return "?";
}

// Errors of the raw link that are not plain errno values.
enum class RawLinkErrc : int {
  kInterfaceNameTooLong = 1,  // empty, or does not fit IFNAMSIZ
  kNotOpen,                   // used after a failed open or after close
  kFrameTooLong,              // more than 1514 bytes
  kFrameTooShort,             // fewer than 14 bytes: not even an Ethernet header
  kBufferTooSmall,            // received frame does not fit the caller's buffer (truncated)
};
[[nodiscard]] const std::error_category& raw_link_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(RawLinkErrc e) noexcept {
  return {static_cast<int>(e), raw_link_category()};
}

struct RawLinkOptions {
  std::string interface;
  RxMode rx_mode = RxMode::Ring;
  // Multicast memberships 01:11:1E:00:00:01..04 are always added; promiscuous mode additionally
  // accepts unicast frames to other MACs (useful when sniffing, not needed by MN or CN).
  bool promiscuous = false;
  bool qdisc_bypass = true;
  uint32_t ring_frames = 256;  // RX ring slots (each 2048 bytes), power of two
  // Ring: how long receive() polls the ring before it blocks in ppoll(); < 0 = to the deadline.
  int64_t ring_spin_ns = -1;
  // The interface flags (IFF_UP / IFF_RUNNING) are re-read at most this often, from send().
  int64_t carrier_check_interval_ns = 10'000'000;
};

struct RawLinkStats {
  uint64_t tx_frames = 0;
  uint64_t tx_errors = 0;
  uint64_t rx_frames = 0;
  uint64_t rx_truncated = 0;  // did not fit the caller's buffer
  uint64_t link_losses = 0;   // up → down transitions seen
  uint64_t kernel_drops = 0;  // PACKET_STATISTICS tp_drops, accumulated by read_kernel_drops()
};

class RawLink final : public Link {
 public:
  RawLink() = default;
  ~RawLink() override;
  RawLink(const RawLink&) = delete;
  RawLink& operator=(const RawLink&) = delete;
  RawLink(RawLink&& other) noexcept;
  RawLink& operator=(RawLink&& other) noexcept;

  // Opens and configures the socket (and the ring). Needs CAP_NET_RAW. On error the link stays
  // closed and the error names the step's errno.
  [[nodiscard]] std::error_code open(const RawLinkOptions& options);
  void close() noexcept;
  [[nodiscard]] bool is_open() const noexcept { return fd_ >= 0; }

  // Link interface. send() pads frames shorter than 60 bytes with zeros (a veth does not pad).
  [[nodiscard]] std::error_code send(std::span<const uint8_t> frame) noexcept override;
  // Waits for one POWERLINK frame until `deadline_ns` (CLOCK_MONOTONIC): its length, length 0
  // when the deadline passed, or an error (link loss, truncated frame). rx_time_ns is taken when
  // the frame is picked up.
  [[nodiscard]] Received receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept override;
  // While up, send() re-reads the interface flags every carrier_check_interval_ns; while down,
  // link_up() itself does (a driver that stops sending on link loss must still see it return).
  [[nodiscard]] bool link_up() const noexcept override;
  [[nodiscard]] MacAddress mac() const noexcept override { return mac_; }

  // Blocks in ppoll() until a frame is ready or the deadline passes, whatever the RX mode. For
  // idle phases where burning a CPU would be wasteful. True if a frame is ready.
  [[nodiscard]] bool wait_readable(int64_t deadline_ns) noexcept;
  // Re-reads the interface flags now (normal thread or rate-limited from send()).
  void refresh_link_state() const noexcept;

  [[nodiscard]] RxMode rx_mode() const noexcept { return options_.rx_mode; }
  [[nodiscard]] const RawLinkStats& stats() const noexcept { return stats_; }
  [[nodiscard]] int ifindex() const noexcept { return ifindex_; }
  // Reads and resets the kernel's drop counter into stats().kernel_drops (one syscall).
  void read_kernel_drops() noexcept;

 private:
  [[nodiscard]] Received receive_ring(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept;
  [[nodiscard]] Received receive_socket(std::span<uint8_t> buffer, int64_t deadline_ns,
                                        bool block) noexcept;
  [[nodiscard]] bool ring_ready() const noexcept;
  void set_up(bool up) const noexcept;
  void move_from(RawLink& other) noexcept;

  RawLinkOptions options_;
  int fd_ = -1;
  int ifindex_ = 0;
  MacAddress mac_{};
  mutable std::atomic<bool> up_{false};
  mutable int64_t next_carrier_check_ns_ = 0;
  // TPACKET_V2 ring mapping.
  uint8_t* ring_ = nullptr;
  std::size_t ring_bytes_ = 0;
  uint32_t ring_frame_size_ = 0;
  uint32_t ring_frame_count_ = 0;
  uint32_t ring_head_ = 0;
  mutable RawLinkStats stats_;
};

}  // namespace ds1928::powerlink

template <>
struct std::is_error_code_enum<ds1928::powerlink::RawLinkErrc> : std::true_type {};
