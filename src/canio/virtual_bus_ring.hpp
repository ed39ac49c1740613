// The virtual CAN bus' shared layout (internal to virtual_bus.cpp and virtual_port.cpp): one
// ring of frame slots, each a seqlock of atomic words, valid in process memory and in POSIX shared
// memory alike (every atomic is lock-free, hence address-free).
#pragma once

#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstring>

#include "canio/virtual_bus.hpp"

namespace ds1928::canio {
namespace vbus {

inline constexpr uint64_t kMagic = 0x4453'3139'5643'414EULL;  // "DS19VCAN"
inline constexpr uint32_t kLayoutVersion = 1;

// One frame on the bus. Every field is an atomic word so that a reader racing a writer (seqlock)
// reads torn values only in a way the sequence check detects, without a data race.
struct Slot {
  // 0: never written; 2t+1: ticket t being written; 2t+2: ticket t complete.
  std::atomic<uint64_t> seq;
  // id (bits 0..28) | extended (29) | rtr (30) | error frame (31) | dlc (32..35) | sender (48..63)
  std::atomic<uint64_t> header;
  std::atomic<uint64_t> data;
  std::atomic<int64_t> wire_ns;  // bus clock when sent
};
static_assert(std::atomic<uint64_t>::is_always_lock_free,
              "the ring lives in shared memory: its atomics must be address-free");

inline uint64_t pack_header(const CanFrame& f, uint16_t sender) noexcept {
  return uint64_t{f.id & kMaxExtendedId} | (uint64_t{f.extended} << 29) | (uint64_t{f.rtr} << 30) |
         (uint64_t{f.error} << 31) | (uint64_t{f.dlc} << 32) | (uint64_t{sender} << 48);
}

inline uint64_t pack_data(const CanFrame& f) noexcept {
  uint64_t d = 0;
  std::memcpy(&d, f.data.data(), 8);
  return d;
}

inline long futex(std::atomic<uint32_t>* word, int op, uint32_t val,
                  const timespec* timeout) noexcept {
  // Shared (not FUTEX_PRIVATE): the word may live in memory mapped by several processes.
  return syscall(SYS_futex, reinterpret_cast<uint32_t*>(word), op, val, timeout, nullptr, 0);
}

}  // namespace vbus

struct VirtualCanBus::Ring {
  uint64_t magic;
  uint32_t version;
  uint32_t capacity;                            // slots, power of two
  std::atomic<uint32_t> ready;                  // 1 once the creator initialised the header
  std::atomic<uint32_t> next_port;              // sender ids
  alignas(64) std::atomic<uint64_t> head;       // next ticket
  alignas(64) std::atomic<uint32_t> published;  // futex word: bumped after every frame
  std::atomic<uint32_t> sleepers;               // readers inside futex wait

  vbus::Slot* slots() noexcept { return reinterpret_cast<vbus::Slot*>(this + 1); }
  static std::size_t bytes(uint32_t capacity) noexcept {
    return sizeof(Ring) + std::size_t{capacity} * sizeof(vbus::Slot);
  }
};
static_assert(alignof(VirtualCanBus::Ring) >= alignof(vbus::Slot));

namespace vbus {
// Writes one frame to the next ticket's slot and wakes sleeping readers.
void publish(VirtualCanBus::Ring& ring, const CanFrame& f, uint16_t sender,
             int64_t wire_ns) noexcept;
}  // namespace vbus

}  // namespace ds1928::canio
