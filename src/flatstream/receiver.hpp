// The receiving half of one Flatstream direction: mirrors the peer's counter while the direction
// is synchronising, takes each sequence whose counter moved by exactly one, reassembles messages
// from control bytes and segments (any layout), and acknowledges only whole sequences.
#pragma once

#include <cstdint>
#include <span>

#include "flatstream/message.hpp"
#include "flatstream/protocol.hpp"

namespace ds1928::flatstream {

enum class ReceiverState : uint8_t {
  Closed,     // SyncAck 0; waiting for the peer to clear its SyncBit
  Mirroring,  // peer's SyncBit 0: ack := counter, nothing taken
  Open,       // synchronised: taking sequences
};
[[nodiscard]] const char* to_string(ReceiverState s) noexcept;

struct ReceiverConfig {
  uint8_t mtu = 7;  // 2..27
  uint16_t forward_delay_us =
      0;  // minimum time between taking two sequences (module: ForwardDelay)
};

struct ReceiverCounters {
  uint64_t messages_received = 0;
  uint64_t sequences_received = 0;  // sequences taken and acknowledged
  uint64_t sequence_gaps = 0;       // times the counter moved by other than 1 (receiver stopped)
  uint64_t resyncs = 0;             // times the peer closed the open direction
  uint64_t partial_discarded = 0;   // incomplete messages dropped by a resync
  uint64_t oversized_dropped = 0;   // complete messages longer than kMaxMessageSize, dropped
  uint64_t stalled_cycles = 0;      // cycles a sequence waited because the receive queue was full
};

class SequenceReceiver {
 public:
  explicit SequenceReceiver(const ReceiverConfig& config) noexcept;
  void configure(const ReceiverConfig& config) noexcept;

  // One bus cycle: the low nibble of the peer's register and its MTU bytes as received.
  void step(uint8_t peer_counter, bool peer_sync_bit, const MtuBytes& bytes,
            uint64_t now_us) noexcept;

  [[nodiscard]] uint8_t ack() const noexcept { return ack_; }
  [[nodiscard]] bool sync_ack() const noexcept { return sync_ack_; }

  [[nodiscard]] bool take(Message& out) noexcept;
  [[nodiscard]] std::size_t pending() const noexcept { return received_.size(); }

  // Back to Closed: the peer sees SyncAck drop and resynchronises. Complete messages stay queued.
  void reset() noexcept;

  [[nodiscard]] ReceiverState state() const noexcept { return state_; }
  [[nodiscard]] const ReceiverCounters& counters() const noexcept { return counters_; }

 private:
  [[nodiscard]] std::size_t completions_in(const MtuBytes& bytes) const noexcept;
  void parse(const MtuBytes& bytes) noexcept;
  void discard_partial() noexcept;

  ReceiverConfig config_;
  ReceiverState state_ = ReceiverState::Closed;
  uint8_t ack_ = 0;
  bool sync_ack_ = false;
  bool stopped_ = false;
  bool taken_ = false;
  uint64_t last_take_us_ = 0;

  // Flow chart state kept across sequences (datasheet figure 8).
  uint8_t remaining_ = 0;  // payload bytes left in the current segment
  uint8_t flags_ = 0;      // nextCBPos / MessageEnd of the current segment
  bool in_message_ = false;
  bool overflow_ = false;
  Message partial_;
  Ring<Message, kQueueDepth> received_;
  ReceiverCounters counters_;
};

}  // namespace ds1928::flatstream
