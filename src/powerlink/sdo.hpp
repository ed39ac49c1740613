// SDO over ASnd (ServiceID 5): client and server as pure state machines (Lely style). Frames come
// in through receive(), time through the `now_ns` arguments, frames go out through the send
// callback as complete Ethernet frames. Neither side sends on its own initiative on the wire:
// the owner queues the frames and sends them in the asynchronous slot it is granted (MN: SoA
// UnspecifiedInvite to itself; CN: when invited). No allocation after construction.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <system_error>

#include "powerlink/frames.hpp"

namespace ds1928::powerlink {

// Largest object a transfer carries (a module register is ≤ 4 bytes; EnDat blocks are larger).
inline constexpr std::size_t kMaxSdoTransfer = 1024;

using FrameSink = std::function<void(std::span<const uint8_t> frame)>;

struct SdoClientConfig {
  uint8_t node = 1;  // the server (CN)
  uint8_t own_node = kNodeMn;
  MacAddress own_mac{};
  int64_t timeout_ns = 500'000'000;
  // Command payload per frame; data above it goes segmented (tests lower it).
  std::size_t max_segment = kMaxSdoSegment - 4;
};

// One transfer at a time per CN; a second request while busy is refused with SdoError::kBusy.
// Cuts one transfer into SDO command-layer segments (EPSG DS 301 §6.3.2.4): a transfer that fits
// one segment goes expedited; a larger one as Initiate (carrying the total size), Segment ...,
// Complete. The client's writes and the server's read responses both send through it. Pure: it
// only counts bytes.
class SdoSegmenter {
 public:
  struct Segment {
    SdoSegmentation segmentation = SdoSegmentation::kExpedited;
    uint32_t total_size = 0;  // Initiate only: the whole transfer
    std::size_t offset = 0;   // of this segment's first byte in the transfer
    std::size_t length = 0;
  };

  void start(std::size_t size) noexcept {
    size_ = size;
    offset_ = 0;
  }
  // The next segment, at most `max_segment` bytes (> 0); call while !done() (or once for an
  // empty transfer, which goes expedited).
  [[nodiscard]] Segment next(std::size_t max_segment) noexcept;
  [[nodiscard]] bool done() const noexcept { return offset_ == size_; }

 private:
  std::size_t size_ = 0;
  std::size_t offset_ = 0;
};

class SdoClient {
 public:
  // `data` is the value read (empty for writes); valid only during the call.
  using Completion = std::function<void(std::error_code, std::span<const uint8_t> data)>;

  SdoClient(const SdoClientConfig& config, FrameSink send, Completion done);

  [[nodiscard]] std::error_code read(uint16_t index, uint8_t subindex, int64_t now_ns) noexcept;
  [[nodiscard]] std::error_code write(uint16_t index, uint8_t subindex,
                                      std::span<const uint8_t> data, int64_t now_ns) noexcept;
  // Aborts the running transfer (sends an abort to the server when connected) and completes it
  // with `reason`.
  void abort(std::error_code reason, int64_t now_ns) noexcept;
  // The node is gone (loss, reset): complete a running transfer with kConnectionLost, forget the
  // connection; the next transfer opens a new one.
  void reset() noexcept;

  // An SDO ASnd from the client's server node.
  void receive(const Sdo& sdo, int64_t now_ns) noexcept;
  // Timeouts.
  void tick(int64_t now_ns) noexcept;

  [[nodiscard]] bool busy() const noexcept { return state_ != State::kIdle; }
  [[nodiscard]] uint8_t node() const noexcept { return config_.node; }

 private:
  enum class State : uint8_t { kIdle, kOpening, kSending, kWaitResponse, kReceiving };
  void send_frame(bool with_command, const SdoCommand& cmd) noexcept;
  void send_ack() noexcept;
  void start_command(int64_t now_ns) noexcept;
  void send_command() noexcept;
  void send_next_write_segment() noexcept;
  void finish(std::error_code ec, std::span<const uint8_t> data) noexcept;

  SdoClientConfig config_;
  FrameSink send_;
  Completion done_;
  State state_ = State::kIdle;
  bool connected_ = false;
  uint8_t send_seq_ = 0;  // our next send sequence number
  uint8_t recv_seq_ = 0;  // last sequence number received from the server
  uint8_t transaction_ = 0;
  bool is_write_ = false;
  uint16_t index_ = 0;
  uint8_t subindex_ = 0;
  std::size_t size_ = 0;      // write: data bytes; read: bytes received so far
  SdoSegmenter segmenter_;    // write: the segments still to send
  std::size_t expected_ = 0;  // read: announced total size
  int64_t deadline_ns_ = 0;
  std::array<uint8_t, kMaxSdoTransfer + 4> buffer_{};
  std::array<uint8_t, kMaxFrameSize> frame_{};
};

// What the server reads and writes: the CN's object dictionary. Return 0 or an SDO abort code.
class SdoObjectAccess {
 public:
  virtual ~SdoObjectAccess() = default;
  [[nodiscard]] virtual uint32_t read_object(uint16_t index, uint8_t subindex,
                                             std::span<uint8_t> out,
                                             std::size_t& size) noexcept = 0;
  [[nodiscard]] virtual uint32_t write_object(uint16_t index, uint8_t subindex,
                                              std::span<const uint8_t> data) noexcept = 0;
};

struct SdoServerConfig {
  uint8_t own_node = 1;
  MacAddress own_mac{};
  uint8_t client_node = kNodeMn;
  int64_t timeout_ns = 2'000'000'000;  // a half-done segmented transfer is dropped after this
  std::size_t max_segment = kMaxSdoSegment - 4;
};

class SdoServer {
 public:
  SdoServer(const SdoServerConfig& config, SdoObjectAccess& objects, FrameSink send);

  // An SDO ASnd addressed to this node.
  void receive(const Sdo& sdo, int64_t now_ns) noexcept;
  void tick(int64_t now_ns) noexcept;
  // NMT reset of the CN: drop the connection.
  void reset() noexcept;

  [[nodiscard]] bool connected() const noexcept { return connected_; }

 private:
  void handle_command(const SdoCommand& cmd, int64_t now_ns) noexcept;
  void send_frame(bool with_command, const SdoCommand& cmd) noexcept;
  void send_abort(uint8_t transaction, uint8_t command_id, uint32_t code) noexcept;
  void send_read_segment() noexcept;

  SdoServerConfig config_;
  SdoObjectAccess& objects_;
  FrameSink send_;
  bool connected_ = false;
  uint8_t send_seq_ = 0;
  uint8_t recv_seq_ = 0;
  // Segmented transfer in progress.
  bool in_write_ = false;
  bool in_read_ = false;
  uint8_t transaction_ = 0;
  uint16_t index_ = 0;
  uint8_t subindex_ = 0;
  std::size_t size_ = 0;
  SdoSegmenter segmenter_;  // read response: the segments still to send
  std::size_t expected_ = 0;
  int64_t deadline_ns_ = 0;
  std::array<uint8_t, kMaxSdoTransfer + 4> buffer_{};
  std::array<uint8_t, kMaxFrameSize> frame_{};
};

}  // namespace ds1928::powerlink
