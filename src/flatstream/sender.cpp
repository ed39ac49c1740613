#include "flatstream/sender.hpp"

#include <algorithm>
#include <cstring>

namespace ds1928::flatstream {
namespace {

SenderConfig clamped(SenderConfig c) noexcept {
  c.mtu = static_cast<uint8_t>(std::clamp<std::size_t>(c.mtu, kMinMtu, kMaxMtu));
  c.forward = std::clamp<uint8_t>(c.forward, 1, kMaxForward);
  c.layout = static_cast<Layout>(static_cast<uint8_t>(c.layout) & 0x03);
  c.timeout_cycles = std::max<uint32_t>(c.timeout_cycles, 1);
  return c;
}

}  // namespace

const char* to_string(SenderState s) noexcept {
  switch (s) {
    case SenderState::Sync0:
      return "sync0";
    case SenderState::Sync1:
      return "sync1";
    case SenderState::Sync2:
      return "sync2";
    case SenderState::Open:
      return "open";
  }
  return "?";
}

SequenceSender::SequenceSender(const SenderConfig& config) noexcept : config_(clamped(config)) {
  enter_sync0();
}

void SequenceSender::configure(const SenderConfig& config) noexcept {
  // A new MTU or layout invalidates every sequence built so far: treat it like a resync.
  interrupt(Errc::unconfirmed);
  config_ = clamped(config);
}

std::error_code SequenceSender::submit(std::span<const uint8_t> message, uint32_t tag) noexcept {
  if (message.size() > kMaxMessageSize) return Errc::message_too_long;
  // A message holds its place until its outcome is taken, so outcomes can never overflow.
  if (queue_.size() + outcomes_.size() >= kQueueDepth) return Errc::queue_full;
  Pending& p = queue_.push_back();
  p.tag = tag;
  p.restarts = 0;
  p.message.size = static_cast<uint16_t>(message.size());
  if (!message.empty()) std::memcpy(p.message.bytes.data(), message.data(), message.size());
  return {};
}

bool SequenceSender::take_outcome(SendOutcome& out) noexcept {
  if (outcomes_.empty()) return false;
  out = outcomes_.front();
  outcomes_.pop_front();
  return true;
}

void SequenceSender::reset() noexcept {
  for (std::size_t i = 0; i < ended_; ++i) report_front(Errc::unconfirmed);
  ended_ = 0;
  while (!queue_.empty()) report_front(Errc::channel_reset);
  msg_offset_ = 0;
  seg_left_ = 0;
  in_segment_ = false;
  enter_sync0();
}

void SequenceSender::enter_sync0() noexcept {
  state_ = SenderState::Sync0;
  counter_ = 0;
  sync_bit_ = false;
  mtu_.fill(0);
  acked_ = sent_ = resend_ = 0;
  resending_ = false;
  stage_cycle_ = cycle_;
  written_ = false;
  rtt_cycles_ = 0;
}

void SequenceSender::report_front(Errc result) noexcept {
  const Pending& p = queue_.front();
  outcomes_.push_back() = SendOutcome{p.tag, result};
  queue_.pop_front();
  if (result == Errc::ok) {
    ++counters_.messages_delivered;
  } else {
    ++counters_.messages_failed;
  }
}

// The direction is closed and has to be synchronised again. What the peer may already hold
// decides each message's fate (see docs/flatstream.md, "Failure after resynchronisation"):
// - its last sequence was sent but not acknowledged: the peer has it completely or not at all,
//   and nobody can tell which → reported failed, never sent again (no duplicate possible);
// - its last sequence was never sent: the peer cannot have completed it and discards the partial
//   when it sees SyncBit 0, which the handshake guarantees before anything new is taken →
//   started again from its first byte (the datasheet's "send the interrupted message again"),
//   unless `partial_reason` is timeout or it was restarted kMaxResends times already.
void SequenceSender::interrupt(Errc partial_reason) noexcept {
  const Errc ended_reason = partial_reason == Errc::timeout ? Errc::timeout : Errc::unconfirmed;
  for (std::size_t i = 0; i < ended_; ++i) report_front(ended_reason);
  ended_ = 0;
  if ((msg_offset_ > 0 || in_segment_) && !queue_.empty()) {
    Pending& p = queue_.front();
    if (partial_reason == Errc::timeout) {
      report_front(Errc::timeout);
    } else if (p.restarts >= kMaxResends) {
      report_front(Errc::resend_limit);
    } else {
      ++p.restarts;
      ++counters_.messages_restarted;
    }
  }
  msg_offset_ = 0;
  seg_left_ = 0;
  in_segment_ = false;
  enter_sync0();
}

uint32_t SequenceSender::repeat_after_cycles() const noexcept {
  // Repeat only once an acknowledgement is overdue compared with the slowest round trip seen, so
  // a loss-free link never repeats; the margin absorbs one late cycle.
  return std::max<uint32_t>(rtt_cycles_, 1) + 2;
}

void SequenceSender::step(uint8_t peer_ack, bool peer_sync_ack, uint64_t now_us) noexcept {
  ++cycle_;
  peer_ack &= 0x07;
  switch (state_) {
    case SenderState::Sync0:
      if (peer_ack == 0 && !peer_sync_ack) {
        state_ = SenderState::Sync1;
        counter_ = 1;
        stage_cycle_ = cycle_;
        return;
      }
      break;
    case SenderState::Sync1:
      if (peer_ack == 1 && !peer_sync_ack) {
        state_ = SenderState::Sync2;
        sync_bit_ = true;
        rtt_cycles_ = static_cast<uint32_t>(cycle_ - stage_cycle_);
        stage_cycle_ = cycle_;
        return;
      }
      break;
    case SenderState::Sync2:
      if (peer_ack == 1 && peer_sync_ack) {
        state_ = SenderState::Open;
        rtt_cycles_ = std::max(rtt_cycles_, static_cast<uint32_t>(cycle_ - stage_cycle_));
        acked_ = sent_ = resend_ = 1;
        resending_ = false;
        // The first sequence may go out in this very cycle: the ack was seen.
        step_open(peer_ack, peer_sync_ack, now_us);
        return;
      }
      break;
    case SenderState::Open:
      step_open(peer_ack, peer_sync_ack, now_us);
      return;
  }
  // Still synchronising: give up on one queued message per timeout period, so a peer that never
  // answers still produces an outcome for everything submitted.
  if (cycle_ - stage_cycle_ > config_.timeout_cycles) {
    if (!queue_.empty()) report_front(Errc::not_synchronised);
    enter_sync0();
  }
}

void SequenceSender::step_open(uint8_t peer_ack, bool peer_sync_ack, uint64_t now_us) noexcept {
  if (!peer_sync_ack) {  // the peer closed the direction
    ++counters_.resyncs;
    interrupt(Errc::unconfirmed);
    return;
  }
  const uint8_t advance = seq_distance(acked_, peer_ack);
  if (advance != 0) {
    // Cumulative: everything up to the ack is delivered. An ack outside the unacknowledged window
    // is for a sequence never sent or acknowledged before: serious error, close and resync.
    if (advance > seq_distance(acked_, sent_)) {
      ++counters_.ack_errors;
      ++counters_.resyncs;
      interrupt(Errc::unconfirmed);
      return;
    }
    rtt_cycles_ =
        std::max(rtt_cycles_, static_cast<uint32_t>(cycle_ - slots_[peer_ack].last_cycle));
    acknowledge_up_to(peer_ack);
  }

  const uint8_t unacked = seq_distance(acked_, sent_);
  if (unacked > 0) {
    const Slot& oldest = slots_[seq_next(acked_)];
    if (cycle_ - oldest.first_cycle > config_.timeout_cycles) {
      ++counters_.timeouts;
      ++counters_.resyncs;
      interrupt(Errc::timeout);
      return;
    }
    // The receiver stopped at a gap (lost sequence) or its acks are lost: go back and repeat
    // every unacknowledged sequence with its original counter.
    if (!resending_ && cycle_ - oldest.last_cycle > repeat_after_cycles()) {
      resending_ = true;
      resend_ = seq_next(acked_);
    }
  }

  if (config_.forward_delay_us != 0 && written_ &&
      now_us - last_write_us_ < config_.forward_delay_us) {
    return;
  }
  if (resending_) {
    Slot& slot = slots_[resend_];
    slot.last_cycle = cycle_;
    write_mtu(slot.bytes, resend_, now_us);
    ++counters_.sequences_repeated;
    if (resend_ == sent_) {
      resending_ = false;
    } else {
      resend_ = seq_next(resend_);
    }
    return;
  }
  if (unacked < config_.forward && has_unsent_data()) {
    const uint8_t next = seq_next(sent_);
    Slot& slot = slots_[next];
    if (build_sequence(slot)) {
      slot.first_cycle = slot.last_cycle = cycle_;
      sent_ = next;
      write_mtu(slot.bytes, next, now_us);
      ++counters_.sequences_sent;
    }
  }
}

void SequenceSender::acknowledge_up_to(uint8_t ack) noexcept {
  const uint8_t advance = seq_distance(acked_, ack);
  if (resending_ && seq_distance(acked_, resend_) <= advance) {
    if (ack == sent_) {
      resending_ = false;
    } else {
      resend_ = seq_next(ack);
    }
  }
  uint8_t c = acked_;
  while (c != ack) {
    c = seq_next(c);
    Slot& slot = slots_[c];
    for (uint8_t i = 0; i < slot.messages_ended; ++i) report_front(Errc::ok);
    ended_ -= slot.messages_ended;
    slot.messages_ended = 0;
  }
  acked_ = ack;
}

void SequenceSender::write_mtu(const MtuBytes& bytes, uint8_t counter, uint64_t now_us) noexcept {
  mtu_ = bytes;
  counter_ = counter;
  written_ = true;
  last_write_us_ = now_us;
  last_write_cycle_ = cycle_;
}

bool SequenceSender::has_unsent_data() const noexcept {
  return in_segment_ || ended_ < queue_.size();
}

// Lays out the next sequence of the send array from the queue (datasheet §11.9.4.4/§11.9.4.9):
// - default: one control byte at the start, segment ≤ MTU−1, tail of the MTU unused;
// - MultiSegmentMTU: after a segment, the next control byte follows in the same MTU; segments
//   still fit in the MTU they start in; nextCBPos is set on every control byte;
// - large segments: segments up to 63 bytes, continuing over following sequences;
// - both: large segments packed back to back.
// With large segments a control byte may take the last byte of an MTU, its payload following
// in the next sequence; the datasheet's receive flow chart (figure 8) reads that as any other
// segment spanning sequences.
bool SequenceSender::build_sequence(Slot& slot) noexcept {
  slot.bytes.fill(0);  // unused bytes read as C0
  slot.messages_ended = 0;
  const std::size_t mtu = config_.mtu;
  const bool multi = multi_segment(config_.layout);
  const bool large = large_segments(config_.layout);
  std::size_t pos = 0;
  while (pos < mtu) {
    if (!in_segment_) {
      if (ended_ >= queue_.size()) break;
      const Message& m = queue_[ended_].message;
      const std::size_t room = mtu - pos;
      const std::size_t left = m.size - msg_offset_;
      // Without large segments a segment must fit where it starts: one free byte is no room.
      if (!large && left > 0 && room < 2) break;
      const std::size_t limit =
          large ? kMaxSegmentLength : std::min<std::size_t>(room - 1, kMaxSegmentLength);
      const auto seg = static_cast<uint8_t>(std::min(left, limit));
      const uint8_t control = cb::make(seg, multi, msg_offset_ + seg == m.size);
      slot.bytes[pos++] = control;
      in_segment_ = true;
      seg_left_ = seg;
      seg_flags_ = control & (cb::kNextCbPos | cb::kMessageEnd);
    }
    const Message& m = queue_[ended_].message;
    const std::size_t n = std::min<std::size_t>(seg_left_, mtu - pos);
    if (n > 0) std::memcpy(&slot.bytes[pos], &m.bytes[msg_offset_], n);
    pos += n;
    msg_offset_ = static_cast<uint16_t>(msg_offset_ + n);
    seg_left_ = static_cast<uint8_t>(seg_left_ - n);
    if (seg_left_ > 0) break;  // segment continues in the next sequence
    in_segment_ = false;
    if ((seg_flags_ & cb::kMessageEnd) != 0) {
      ++ended_;
      ++slot.messages_ended;
      msg_offset_ = 0;
    }
    if ((seg_flags_ & cb::kNextCbPos) == 0) break;
  }
  return pos > 0;
}

}  // namespace ds1928::flatstream
