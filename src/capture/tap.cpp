#include "capture/tap.hpp"

#include <sched.h>

#include <algorithm>
#include <cstring>
#include <new>
#include <stdexcept>

#include "core/clock.hpp"
#include "core/single_writer.hpp"

namespace ds1928::capture {

Tap::Tap(std::string name, uint16_t link_type, std::size_t max_frame, std::size_t ring_frames)
    : name_(std::move(name)),
      link_type_(link_type),
      max_frame_(std::min<std::size_t>(max_frame, UINT16_MAX)),
      capacity_(ring_frames),
      // Slots on cache-line boundaries: the producer's copy never shares a line with the slot the
      // consumer reads.
      slot_size_((sizeof(Header) + max_frame_ + 63) / 64 * 64) {
  if (ring_frames < 2 || (ring_frames & (ring_frames - 1)) != 0)
    throw std::invalid_argument("capture ring of " + std::to_string(ring_frames) +
                                " frames: must be a power of two, at least 2");
  // The ring exists only while a capture runs (begin() .. release()): a POWERLINK tap's ring
  // is 6.5 MiB at the default 4096 slots, which an idle daemon should not keep resident.
}

void Tap::record(Direction direction, int64_t time_ns, std::span<const uint8_t> bytes) noexcept {
  const uint64_t seq = seq_.load(std::memory_order_relaxed) + 1;
  seq_.store(seq, std::memory_order_seq_cst);
  single_writer_add(direction == Direction::Outbound ? tx_ : rx_);
  if (flight_) {
    if (time_ns == 0) time_ns = rt::now_ns();
    flight_->record(direction, time_ns, bytes);
  }
  // ring_ is set before active_ turns true and freed only after release() saw every producer
  // that could have seen active_ true finish (both through the sequentially consistent pair).
  if (active_.load(std::memory_order_seq_cst) && ring_ != nullptr) {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) == capacity_) {
      single_writer_add(dropped_);
    } else {
      uint8_t* slot = slot_at(head);
      const std::size_t length = std::min(bytes.size(), max_frame_);
      const Header h{seq, time_ns != 0 ? time_ns : rt::now_ns(), static_cast<uint16_t>(length),
                     static_cast<uint8_t>(direction)};
      std::memcpy(slot, &h, sizeof h);
      if (length != 0) std::memcpy(slot + sizeof h, bytes.data(), length);
      head_.store(head + 1, std::memory_order_release);
      single_writer_add(captured_);
    }
  }
  done_.store(seq, std::memory_order_release);
}

uint64_t Tap::begin() noexcept {
  if (ring_ == nullptr) {
    // Value-initialised: every page is touched here, on the normal thread, not by the cycle
    // thread's first copy. Without memory the capture records nothing: every frame of the
    // window counts as dropped.
    ring_.reset(new (std::nothrow) uint8_t[capacity_ * slot_size_]());
    tail_.store(head_.load(std::memory_order_relaxed), std::memory_order_relaxed);
  }
  active_.store(true, std::memory_order_seq_cst);
  return seq_.load(std::memory_order_seq_cst);
}

uint64_t Tap::finish() noexcept {
  const uint64_t end = seq_.load(std::memory_order_seq_cst);
  // The producer stores done_ right after seq_ within one record() call (no syscall between):
  // this wait is a few hundred nanoseconds unless the producer was preempted in between.
  while (done_.load(std::memory_order_acquire) < end) sched_yield();
  active_.store(false, std::memory_order_seq_cst);
  return end;
}

void Tap::deactivate() noexcept {
  active_.store(false, std::memory_order_seq_cst);
}

void Tap::release() noexcept {
  active_.store(false, std::memory_order_seq_cst);
  // A producer that saw active_ true has stored its sequence number before (seq_cst), so it is
  // at most `seen`; once done_ reaches it, nobody is or will be in the ring.
  const uint64_t seen = seq_.load(std::memory_order_seq_cst);
  while (done_.load(std::memory_order_acquire) < seen) sched_yield();
  tail_.store(head_.load(std::memory_order_acquire), std::memory_order_release);
  ring_.reset();
}

TapCounters Tap::counters() const noexcept {
  return {seq_.load(std::memory_order_acquire), tx_.load(std::memory_order_relaxed),
          rx_.load(std::memory_order_relaxed), captured_.load(std::memory_order_relaxed),
          dropped_.load(std::memory_order_relaxed)};
}

}  // namespace ds1928::capture
