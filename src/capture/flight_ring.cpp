#include "capture/flight_ring.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "core/single_writer.hpp"

namespace ds1928::capture {
namespace {

uint64_t header_word(std::size_t length, Direction d, uint64_t kind) noexcept {
  return static_cast<uint64_t>(length) | (uint64_t{static_cast<uint8_t>(d)} << 16) | (kind << 24);
}

}  // namespace

FlightRing::FlightRing(std::size_t bytes, std::size_t max_frame)
    : max_frame_(std::min<std::size_t>(max_frame, UINT16_MAX)), capacity_(bytes / 8) {
  const uint64_t largest = kHeaderWords + (max_frame_ + 7) / 8;
  if (capacity_ < 4 * largest)
    throw std::invalid_argument("flight recorder ring of " + std::to_string(bytes) +
                                " bytes: too small for 4 frames of " + std::to_string(max_frame_) +
                                " bytes (at least " + std::to_string(4 * largest * 8) + ")");
  // Value-initialised: every page is touched now, not by the cycle thread's first record.
  words_ = std::make_unique<std::atomic<uint64_t>[]>(capacity_);
  for (uint64_t i = 0; i < capacity_; ++i) words_[i].store(0, std::memory_order_relaxed);
}

uint64_t FlightRing::record_words(uint64_t pos) const noexcept {
  const uint64_t r = room(pos);
  if (r < kHeaderWords) return r;  // nothing fits here: the next record starts at word 0
  const uint64_t h = word(pos + 2).load(std::memory_order_relaxed);
  if ((h >> 24 & 0xFF) != kKindFrame) return r;  // pad to the end
  return kHeaderWords + ((h & 0xFFFF) + 7) / 8;
}

void FlightRing::record(Direction direction, int64_t time_ns,
                        std::span<const uint8_t> bytes) noexcept {
  const std::size_t length = std::min(bytes.size(), max_frame_);
  const uint64_t need = kHeaderWords + (length + 7) / 8;
  uint64_t pos = head_local_;
  const uint64_t pad = room(pos) < need ? room(pos) : 0;
  const uint64_t end = pos + pad + need;
  // The oldest records this one overwrites are gone: the tail moves past them first.
  uint64_t tail = tail_local_;
  uint64_t gone = 0;
  while (tail + capacity_ < end) {
    const uint64_t w = record_words(tail);
    if (room(tail) >= kHeaderWords &&
        (word(tail + 2).load(std::memory_order_relaxed) >> 24 & 0xFF) == kKindFrame)
      ++gone;
    tail += w;
  }
  tail_local_ = tail;
  tail_.store(tail, std::memory_order_relaxed);
  reserve_.store(end, std::memory_order_release);
  // Every word written below is ordered after `reserve` (the reader's check).
  std::atomic_thread_fence(std::memory_order_release);
  if (pad >= kHeaderWords) {
    word(pos).store(0, std::memory_order_relaxed);
    word(pos + 1).store(0, std::memory_order_relaxed);
    word(pos + 2).store(header_word(0, Direction::Unknown, kKindPad), std::memory_order_relaxed);
  }
  pos += pad;
  word(pos).store(++seq_local_, std::memory_order_relaxed);
  word(pos + 1).store(static_cast<uint64_t>(time_ns), std::memory_order_relaxed);
  word(pos + 2).store(header_word(length, direction, kKindFrame), std::memory_order_relaxed);
  for (std::size_t off = 0, w = 3; off < length; off += 8, ++w) {
    uint64_t v = 0;
    std::memcpy(&v, bytes.data() + off, std::min<std::size_t>(8, length - off));
    word(pos + w).store(v, std::memory_order_relaxed);
  }
  head_local_ = end;
  head_.store(end, std::memory_order_release);
  single_writer_add(frames_);
  if (gone != 0) single_writer_add(overwritten_, gone);
  if (bytes.size() > length) single_writer_add(cut_);
}

std::vector<FlightFrame> FlightRing::frames_since(int64_t from_ns) const {
  std::vector<FlightFrame> out;
  const uint64_t head = head_.load(std::memory_order_acquire);
  uint64_t pos = tail_.load(std::memory_order_acquire);
  // Whether the record at `pos` may have been overwritten while it was read; if so, `pos` moves
  // to the producer's tail (which is past everything overwritten).
  auto overtaken = [&](uint64_t at) {
    std::atomic_thread_fence(std::memory_order_acquire);
    const uint64_t reserve = reserve_.load(std::memory_order_acquire);
    if (at + capacity_ >= reserve) return false;
    pos = std::max(at, tail_.load(std::memory_order_acquire));
    return true;
  };
  while (pos < head) {
    const uint64_t r = room(pos);
    if (r < kHeaderWords) {
      pos += r;
      continue;
    }
    const uint64_t seq = word(pos).load(std::memory_order_relaxed);
    const auto time = static_cast<int64_t>(word(pos + 1).load(std::memory_order_relaxed));
    const uint64_t h = word(pos + 2).load(std::memory_order_relaxed);
    if (overtaken(pos)) continue;
    const uint64_t kind = h >> 24 & 0xFF;
    const std::size_t length = h & 0xFFFF;
    if (kind == kKindPad) {
      pos += r;
      continue;
    }
    // Intact and not a frame or longer than any frame kept: the ring is corrupt; stop here.
    if (kind != kKindFrame || length > max_frame_) break;
    const uint64_t words = kHeaderWords + (length + 7) / 8;
    if (time < from_ns) {
      pos += words;
      continue;
    }
    FlightFrame f;
    f.seq = seq;
    f.time_ns = time;
    f.direction = static_cast<Direction>(h >> 16 & 0xFF);
    f.bytes.resize(length);
    for (std::size_t off = 0, w = 3; off < length; off += 8, ++w) {
      const uint64_t v = word(pos + w).load(std::memory_order_relaxed);
      std::memcpy(f.bytes.data() + off, &v, std::min<std::size_t>(8, length - off));
    }
    if (overtaken(pos)) continue;
    out.push_back(std::move(f));
    pos += words;
  }
  return out;
}

FlightRingCounters FlightRing::counters() const noexcept {
  return {frames_.load(std::memory_order_relaxed), overwritten_.load(std::memory_order_relaxed),
          cut_.load(std::memory_order_relaxed)};
}

}  // namespace ds1928::capture
