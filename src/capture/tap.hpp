// A capture point on one link or port: counts every frame the bus driver sends or receives
// through it and, while a capture is active, copies each into a fixed ring that the normal
// thread drains. The thread that owns the link/port (the cycle thread, which also steps CAN-I/O's
// SDO transfers on their own port) is the single producer; the capture service on the normal
// thread is the single consumer.
//
// Producer side: record() never allocates, locks or blocks; a full ring drops the frame and
// counts it. The ring (ring_frames slots of max_frame bytes) is allocated by the consumer when a
// capture begins and freed by release() when it is over, so that an idle daemon does not keep
// it resident.
//
// The exact window: every frame gets a sequence number (frames seen by this tap since it was
// made). begin() activates the tap and returns S; a frame numbered above S is then either in the
// ring or dropped. finish() returns E once frame E is fully handled and deactivates the tap. The
// capture holds the frames numbered S+1..E: frames in the window = E - S = captured + dropped,
// with no frame of the window unaccounted for, whatever the timing of begin/finish against the
// producer (begin: sequentially consistent store of `active` before the load of `seq`, against
// the producer's store of `seq` before its load of `active`).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <string>

#include "capture/flight_ring.hpp"
#include "capture/pcapng.hpp"

namespace ds1928::capture {

// One frame as the consumer gets it.
struct TapFrame {
  uint64_t seq = 0;
  int64_t time_ns = 0;  // CLOCK_MONOTONIC: reception time (RX) or send time (TX)
  Direction direction = Direction::Unknown;
  std::span<const uint8_t> bytes;
};

// Counters since the tap was made. Any thread; each field exact, the set not one instant.
struct TapCounters {
  uint64_t frames = 0;     // every frame seen (= the last sequence number)
  uint64_t tx_frames = 0;  // sent
  uint64_t rx_frames = 0;  // received (error frames included)
  uint64_t captured = 0;   // copied into the ring
  uint64_t dropped = 0;    // seen while a capture was active, lost to a full ring
};

class Tap {
 public:
  // `name`: interface/port name for the capture file; `link_type`: its LINKTYPE_*;
  // `max_frame`: largest frame recorded (longer ones are cut); `ring_frames`: power of two.
  Tap(std::string name, uint16_t link_type, std::size_t max_frame, std::size_t ring_frames);
  Tap(const Tap&) = delete;
  Tap& operator=(const Tap&) = delete;

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] uint16_t link_type() const noexcept { return link_type_; }
  [[nodiscard]] std::size_t ring_frames() const noexcept { return capacity_; }
  // What the point is, for the capture file's interface description ("SDO port"). Set before
  // the first capture.
  void set_description(std::string text) { description_ = std::move(text); }
  [[nodiscard]] const std::string& description() const noexcept { return description_; }

  // The flight recorder's ring this point always records into (flight_ring.hpp), sized for its
  // frames (max_frame()). Normal thread, before the producer starts; the tap owns it.
  void attach_flight_ring(std::size_t bytes) {
    flight_ = std::make_unique<FlightRing>(bytes, max_frame_);
  }
  [[nodiscard]] const FlightRing* flight_ring() const noexcept { return flight_.get(); }
  [[nodiscard]] std::size_t max_frame() const noexcept { return max_frame_; }

  // ---- producer -------------------------------------------------------------------------------
  // Counts the frame, records it in the flight ring (if any) and, while active, copies it.
  // `time_ns` 0: now (CLOCK_MONOTONIC), read only when the frame is kept.
  void record(Direction direction, int64_t time_ns, std::span<const uint8_t> bytes) noexcept;

  // ---- consumer (one capture at a time) -------------------------------------------------------
  // Activates the tap; returns S (frames numbered S+1.. belong to the capture).
  [[nodiscard]] uint64_t begin() noexcept;
  // Waits (briefly: the producer is between two stores of one record() call) until frame E =
  // the current count is fully handled, deactivates the tap and returns E.
  [[nodiscard]] uint64_t finish() noexcept;
  // Deactivates without a window end (a capture that stops at a frame it already has).
  void deactivate() noexcept;
  // After the capture: deactivates, waits (briefly) until no producer can be in the ring any
  // more, drops what it still holds and frees it. The next begin() allocates it again.
  void release() noexcept;
  // Whether the ring is allocated (between begin() and release()).
  [[nodiscard]] bool has_ring() const noexcept { return ring_ != nullptr; }
  [[nodiscard]] bool active() const noexcept { return active_.load(std::memory_order_relaxed); }
  // Hands the oldest frame to `f` and releases its slot; false when the ring is empty. The span
  // is valid during the call only.
  template <typename F>
  bool pop(F&& f) {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_.load(std::memory_order_acquire)) return false;
    const uint8_t* slot = slot_at(tail);
    Header h;
    std::memcpy(&h, slot, sizeof h);
    f(TapFrame{h.seq, h.time_ns, static_cast<Direction>(h.direction),
               std::span<const uint8_t>(slot + sizeof(Header), h.length)});
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  // ---- any thread -----------------------------------------------------------------------------
  [[nodiscard]] TapCounters counters() const noexcept;

 private:
  struct Header {
    uint64_t seq;
    int64_t time_ns;
    uint16_t length;
    uint8_t direction;
  };
  [[nodiscard]] uint8_t* slot_at(std::size_t index) const noexcept {
    return ring_.get() + (index & (capacity_ - 1)) * slot_size_;
  }

  std::string name_;
  std::string description_;
  uint16_t link_type_;
  std::size_t max_frame_;
  std::size_t capacity_;
  std::size_t slot_size_;
  std::unique_ptr<uint8_t[]> ring_;
  std::unique_ptr<FlightRing> flight_;

  alignas(64) std::atomic<std::size_t> head_{0};  // producer
  std::atomic<uint64_t> seq_{0};
  std::atomic<uint64_t> done_{0};
  std::atomic<uint64_t> tx_{0};
  std::atomic<uint64_t> rx_{0};
  std::atomic<uint64_t> captured_{0};
  std::atomic<uint64_t> dropped_{0};
  alignas(64) std::atomic<std::size_t> tail_{0};  // consumer
  std::atomic<bool> active_{false};
};

}  // namespace ds1928::capture
