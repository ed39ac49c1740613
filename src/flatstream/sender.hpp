// The sending half of one Flatstream direction: queue of messages → segments and control bytes
// → one MTU sequence per bus cycle, with synchronisation, Forward (pipelining), acknowledgement
// checks, go-back repetition and timeouts. Role-neutral; MasterChannel and ModuleChannel wrap it.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <system_error>

#include "flatstream/message.hpp"
#include "flatstream/protocol.hpp"

namespace ds1928::flatstream {

// How often a message interrupted by a resynchronisation (before its last sequence went out) is
// started again before it is reported failed (Errc::resend_limit).
inline constexpr uint8_t kMaxResends = 3;

enum class SenderState : uint8_t {
  Sync0,  // counter 000, SyncBit 0; waiting for ack 000 / SyncAck 0
  Sync1,  // counter 001, SyncBit 0; waiting for ack 001 / SyncAck 0
  Sync2,  // counter 001, SyncBit 1; waiting for ack 001 / SyncAck 1
  Open,   // synchronised: sending
};
[[nodiscard]] const char* to_string(SenderState s) noexcept;

struct SenderConfig {
  uint8_t mtu = 7;                  // 2..27
  Layout layout = Layout::Default;  // how the send array is laid out
  uint8_t forward = 1;              // unacknowledged sequences allowed, 1..7
  uint16_t forward_delay_us = 0;    // minimum time between two MTU writes (module: ForwardDelay)
  uint32_t timeout_cycles = 200;    // a sequence unacknowledged this long fails its message
};

struct SenderCounters {
  uint64_t messages_delivered = 0;  // all sequences acknowledged
  uint64_t messages_failed = 0;     // reported with an error
  uint64_t messages_restarted = 0;  // interrupted by a resync and started again from the front
  uint64_t sequences_sent = 0;      // new sequences (counter advanced to a new value)
  uint64_t sequences_repeated = 0;  // sequences written again with their original counter
  uint64_t resyncs = 0;             // times this direction left the open state
  uint64_t ack_errors = 0;          // ack of a sequence never sent or already acknowledged
  uint64_t timeouts = 0;            // sequence timeouts
};

class SequenceSender {
 public:
  explicit SequenceSender(const SenderConfig& config) noexcept;

  // New configuration; the direction starts again from Sync0 and queued messages are kept.
  void configure(const SenderConfig& config) noexcept;

  // Queue a message. Errc::message_too_long / Errc::queue_full, else ok.
  [[nodiscard]] std::error_code submit(std::span<const uint8_t> message, uint32_t tag) noexcept;
  [[nodiscard]] bool take_outcome(SendOutcome& out) noexcept;

  // One bus cycle. `peer_ack` / `peer_sync_ack` are the high nibble of the peer's register as
  // received this cycle. Afterwards counter(), sync_bit() and mtu() hold what to send.
  void step(uint8_t peer_ack, bool peer_sync_ack, uint64_t now_us) noexcept;

  [[nodiscard]] uint8_t counter() const noexcept { return counter_; }
  [[nodiscard]] bool sync_bit() const noexcept { return sync_bit_; }
  [[nodiscard]] const MtuBytes& mtu() const noexcept { return mtu_; }

  // Every queued and in-flight message is reported Errc::channel_reset; back to Sync0.
  void reset() noexcept;

  [[nodiscard]] SenderState state() const noexcept { return state_; }
  [[nodiscard]] const SenderCounters& counters() const noexcept { return counters_; }
  [[nodiscard]] const SenderConfig& config() const noexcept { return config_; }
  [[nodiscard]] std::size_t queued() const noexcept { return queue_.size(); }
  [[nodiscard]] uint8_t unacknowledged() const noexcept { return seq_distance(acked_, sent_); }

 private:
  struct Pending {
    uint32_t tag = 0;
    uint8_t restarts = 0;
    Message message;
  };
  struct Slot {  // one sent, not yet acknowledged sequence, indexed by its counter
    MtuBytes bytes{};
    uint8_t messages_ended = 0;  // messages whose last byte is in this sequence
    uint64_t first_cycle = 0;    // first transmission (timeout)
    uint64_t last_cycle = 0;     // latest transmission (go-back)
  };

  void enter_sync0() noexcept;
  void step_open(uint8_t peer_ack, bool peer_sync_ack, uint64_t now_us) noexcept;
  void acknowledge_up_to(uint8_t ack) noexcept;
  void interrupt(Errc partial_reason) noexcept;
  void report_front(Errc result) noexcept;
  void write_mtu(const MtuBytes& bytes, uint8_t counter, uint64_t now_us) noexcept;
  [[nodiscard]] bool build_sequence(Slot& slot) noexcept;
  [[nodiscard]] bool has_unsent_data() const noexcept;
  [[nodiscard]] uint32_t repeat_after_cycles() const noexcept;

  SenderConfig config_;
  SenderState state_ = SenderState::Sync0;
  uint8_t counter_ = 0;
  bool sync_bit_ = false;
  MtuBytes mtu_{};

  // Window: sequences acked_+1 .. sent_ are unacknowledged; go-back rewrites them from resend_.
  uint8_t acked_ = 0;
  uint8_t sent_ = 0;
  uint8_t resend_ = 0;
  bool resending_ = false;
  std::array<Slot, 8> slots_{};

  // Queue: [0, ended_) have their last byte in unacknowledged sequences; message ended_ is being
  // segmented (cursor below); the rest are untouched.
  Ring<Pending, kQueueDepth> queue_;
  Ring<SendOutcome, kQueueDepth> outcomes_;
  std::size_t ended_ = 0;
  uint16_t msg_offset_ = 0;  // bytes of message ended_ already placed
  uint8_t seg_left_ = 0;     // payload bytes of the open segment still to place
  uint8_t seg_flags_ = 0;    // nextCBPos / MessageEnd of the open segment
  bool in_segment_ = false;

  uint64_t cycle_ = 0;
  uint64_t stage_cycle_ = 0;    // when the current sync stage began
  uint64_t last_write_us_ = 0;  // ForwardDelay reference
  bool written_ = false;
  uint64_t last_write_cycle_ = 0;
  uint32_t rtt_cycles_ = 0;  // longest round trip seen since synchronising (go-back timer)
  SenderCounters counters_;
};

}  // namespace ds1928::flatstream
