// The flight recorder's ring: the last frames a capture point saw, always on (docs/operations.md
// "Flight recorder"). Bounded in bytes, allocated and touched once at construction; the producer
// (the thread that owns the link/port: the cycle thread) overwrites the oldest frames and never
// allocates, locks, blocks or waits for the reader. The reader (the incident service, normal
// thread) copies the frames out while the producer goes on, and takes only what it read intact.
//
// Layout: records of whole 64-bit words — [sequence][time_ns][length | direction << 16 | kind <<
// 24][frame bytes, padded to 8] — one after the other in a circle of words; a record never wraps:
// where it does not fit before the end, a pad record (or, with fewer than 3 words left, nothing)
// fills the rest and it starts at word 0. Positions are counted in words since the start and
// never wrap (64 bits).
//
// Reading what is being overwritten (a seqlock over a byte range): before it writes a record the
// producer publishes `reserve` = the end of what it is about to write, then a release fence; the
// reader copies a record, then an acquire fence, then loads `reserve`: a record at position p is
// intact iff p >= reserve - capacity. Frame bytes are relaxed atomic words, so a torn read is
// detected, never undefined. `tail` (the oldest intact record) is where the reader starts and
// where it resumes when the producer overtook it.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "capture/pcapng.hpp"

namespace ds1928::capture {

struct FlightFrame {
  uint64_t seq = 0;     // frames recorded by this ring before this one + 1
  int64_t time_ns = 0;  // CLOCK_MONOTONIC
  Direction direction = Direction::Unknown;
  std::vector<uint8_t> bytes;
};

struct FlightRingCounters {
  uint64_t frames = 0;       // recorded since the ring was made
  uint64_t overwritten = 0;  // of those, gone (the ring's bound)
  uint64_t cut = 0;          // longer than the ring's max_frame: recorded cut
};

class FlightRing {
 public:
  // `bytes`: the ring's size (rounded down to whole words; at least room for 4 frames of
  // `max_frame`); `max_frame`: the longest frame kept whole (longer ones are cut).
  FlightRing(std::size_t bytes, std::size_t max_frame);
  FlightRing(const FlightRing&) = delete;
  FlightRing& operator=(const FlightRing&) = delete;

  [[nodiscard]] std::size_t capacity_bytes() const noexcept { return capacity_ * 8; }
  [[nodiscard]] std::size_t max_frame() const noexcept { return max_frame_; }

  // ---- producer (one thread) -----------------------------------------------------------------
  void record(Direction direction, int64_t time_ns, std::span<const uint8_t> bytes) noexcept;

  // ---- reader (one thread at a time, any) ----------------------------------------------------
  // Every intact frame with time_ns >= from_ns, oldest first, up to what was recorded when the
  // call began (a frame recorded during the call may or may not be among them).
  [[nodiscard]] std::vector<FlightFrame> frames_since(int64_t from_ns) const;
  [[nodiscard]] FlightRingCounters counters() const noexcept;

 private:
  static constexpr uint64_t kHeaderWords = 3;
  static constexpr uint64_t kKindFrame = 1;
  static constexpr uint64_t kKindPad = 2;

  [[nodiscard]] std::atomic<uint64_t>& word(uint64_t pos) const noexcept {
    return words_[pos % capacity_];
  }
  [[nodiscard]] uint64_t room(uint64_t pos) const noexcept { return capacity_ - pos % capacity_; }
  // Words of the record at `pos` (producer: its own writes; reader: validated afterwards).
  [[nodiscard]] uint64_t record_words(uint64_t pos) const noexcept;

  std::size_t max_frame_;
  uint64_t capacity_;  // words
  std::unique_ptr<std::atomic<uint64_t>[]> words_;

  // Producer's own view.
  uint64_t head_local_ = 0;
  uint64_t tail_local_ = 0;
  uint64_t seq_local_ = 0;

  alignas(64) std::atomic<uint64_t> head_{0};  // end of the last complete record
  std::atomic<uint64_t> reserve_{0};           // end of what the producer is writing
  std::atomic<uint64_t> tail_{0};              // start of the oldest intact record
  std::atomic<uint64_t> frames_{0};
  std::atomic<uint64_t> overwritten_{0};
  std::atomic<uint64_t> cut_{0};
};

}  // namespace ds1928::capture
