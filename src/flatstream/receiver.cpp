#include "flatstream/receiver.hpp"

#include <algorithm>
#include <cstring>

namespace ds1928::flatstream {

const char* to_string(ReceiverState s) noexcept {
  switch (s) {
    case ReceiverState::Closed:
      return "closed";
    case ReceiverState::Mirroring:
      return "mirroring";
    case ReceiverState::Open:
      return "open";
  }
  return "?";
}

SequenceReceiver::SequenceReceiver(const ReceiverConfig& config) noexcept {
  configure(config);
}

void SequenceReceiver::configure(const ReceiverConfig& config) noexcept {
  config_ = config;
  config_.mtu = static_cast<uint8_t>(std::clamp<std::size_t>(config_.mtu, kMinMtu, kMaxMtu));
  reset();
}

void SequenceReceiver::reset() noexcept {
  discard_partial();
  state_ = ReceiverState::Closed;
  ack_ = 0;
  sync_ack_ = false;
  stopped_ = false;
  taken_ = false;
}

bool SequenceReceiver::take(Message& out) noexcept {
  if (received_.empty()) return false;
  const Message& m = received_.front();
  out.size = m.size;
  std::memcpy(out.bytes.data(), m.bytes.data(), m.size);
  received_.pop_front();
  return true;
}

void SequenceReceiver::discard_partial() noexcept {
  if (in_message_) ++counters_.partial_discarded;
  in_message_ = false;
  overflow_ = false;
  remaining_ = 0;
  flags_ = 0;
  partial_.size = 0;
}

void SequenceReceiver::step(uint8_t peer_counter, bool peer_sync_bit, const MtuBytes& bytes,
                            uint64_t now_us) noexcept {
  peer_counter &= 0x07;
  if (!peer_sync_bit) {
    // The peer (re)starts the handshake. Whatever was half received can never be completed: the
    // sender starts every message again from its first byte after a resync.
    if (state_ == ReceiverState::Open) ++counters_.resyncs;
    discard_partial();
    state_ = ReceiverState::Mirroring;
    ack_ = peer_counter;
    sync_ack_ = false;
    stopped_ = false;
    return;
  }
  switch (state_) {
    case ReceiverState::Closed:
      return;  // SyncAck stays 0 until the peer goes through SyncBit 0
    case ReceiverState::Mirroring:
      // Step 3 of the handshake: SyncBit set on the counter we mirrored.
      if (peer_counter == ack_) {
        discard_partial();
        state_ = ReceiverState::Open;
        sync_ack_ = true;
        taken_ = false;
      }
      return;
    case ReceiverState::Open:
      break;
  }

  const uint8_t moved = seq_distance(ack_, peer_counter);
  if (moved == 0) return;  // same sequence again (bus kept the last valid values)
  if (moved != 1) {
    // Lost sequence (Forward) or a repeat of one already taken: stop until the expected counter
    // comes again; no acks meanwhile, which makes the sender go back.
    if (!stopped_) {
      stopped_ = true;
      ++counters_.sequence_gaps;
    }
    return;
  }
  if (config_.forward_delay_us != 0 && taken_ &&
      now_us - last_take_us_ < config_.forward_delay_us) {
    return;
  }
  // Acknowledge only what can be stored whole: a full receive queue holds the sequence back and
  // the sender waits (or repeats it) instead of losing a message.
  if (completions_in(bytes) > received_.capacity() - received_.size()) {
    ++counters_.stalled_cycles;
    return;
  }
  parse(bytes);
  ack_ = peer_counter;
  stopped_ = false;
  taken_ = true;
  last_take_us_ = now_us;
  ++counters_.sequences_received;
}

// Same walk as parse(), counting message ends only.
std::size_t SequenceReceiver::completions_in(const MtuBytes& bytes) const noexcept {
  const std::size_t mtu = config_.mtu;
  std::size_t pos = 0;
  std::size_t remaining = remaining_;
  uint8_t flags = flags_;
  std::size_t completions = 0;
  while (pos < mtu) {
    if (remaining == 0) {
      const uint8_t control = bytes[pos++];
      if (control == cb::kIdle) break;
      remaining = control & cb::kLengthMask;
      flags = control & (cb::kNextCbPos | cb::kMessageEnd);
    }
    const std::size_t n = std::min(remaining, mtu - pos);
    pos += n;
    remaining -= n;
    if (remaining > 0) break;
    if ((flags & cb::kMessageEnd) != 0) ++completions;
    if ((flags & cb::kNextCbPos) == 0) break;
  }
  return completions;
}

// Datasheet figure 8. A segment ending exactly at the end of the MTU reads the same with
// nextCBPos 0 or 1: the next control byte is the first byte of the next sequence either way.
void SequenceReceiver::parse(const MtuBytes& bytes) noexcept {
  const std::size_t mtu = config_.mtu;
  std::size_t pos = 0;
  while (pos < mtu) {
    if (remaining_ == 0) {
      const uint8_t control = bytes[pos++];
      if (control == cb::kIdle) break;  // C0: nothing more in this MTU
      remaining_ = control & cb::kLengthMask;
      flags_ = control & (cb::kNextCbPos | cb::kMessageEnd);
      in_message_ = true;
    }
    const std::size_t n = std::min<std::size_t>(remaining_, mtu - pos);
    if (partial_.size + n > kMaxMessageSize) {
      overflow_ = true;
    } else if (!overflow_ && n > 0) {
      std::memcpy(&partial_.bytes[partial_.size], &bytes[pos], n);
      partial_.size = static_cast<uint16_t>(partial_.size + n);
    }
    pos += n;
    remaining_ = static_cast<uint8_t>(remaining_ - n);
    if (remaining_ > 0) break;  // segment continues in the next sequence
    if ((flags_ & cb::kMessageEnd) != 0) {
      if (overflow_) {
        ++counters_.oversized_dropped;
      } else {
        Message& out = received_.push_back();  // room checked by completions_in()
        out.size = partial_.size;
        std::memcpy(out.bytes.data(), partial_.bytes.data(), partial_.size);
        ++counters_.messages_received;
      }
      partial_.size = 0;
      overflow_ = false;
      in_message_ = false;
    }
    if ((flags_ & cb::kNextCbPos) == 0) break;
  }
}

}  // namespace ds1928::flatstream
