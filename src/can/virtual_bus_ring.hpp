// The virtual CAN bus' shared layout (internal to virtual_bus.cpp and virtual_port.cpp): one
// ring of frame slots, each a seqlock of atomic words, valid in process memory and in POSIX shared
// memory alike (every atomic is lock-free, hence address-free). A timed bus (bitrate != 0) adds
// one TX queue per port in the same memory and the bus timeline (when the wire is free again).
#pragma once

#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstring>

#include "can/virtual_bus.hpp"

namespace ds1928::canio {
namespace vbus {

inline constexpr uint64_t kMagic = 0x4453'3139'5643'414EULL;  // "DS19VCAN"
inline constexpr uint32_t kLayoutVersion = 2;
// Ports of one timed bus that can hold a TX queue at the same time (in all processes together).
inline constexpr uint32_t kTxQueues = 32;
// Frames one port's TX queue holds (power of two): a send beyond it answers QueueFull (ENOBUFS).
inline constexpr uint32_t kTxDepth = 32;

// One frame on the bus. Every field is an atomic word so that a reader racing a writer (seqlock)
// reads torn values only in a way the sequence check detects, without a data race.
struct Slot {
  // 0: never written; 2t+1: ticket t being written; 2t+2: ticket t complete.
  std::atomic<uint64_t> seq;
  // id (bits 0..28) | extended (29) | rtr (30) | error frame (31) | dlc (32..35) | sender (48..63)
  std::atomic<uint64_t> header;
  std::atomic<uint64_t> data;
  std::atomic<int64_t> wire_ns;   // RX stamp: bus clock when sent (instant) / end of frame (timed)
  std::atomic<int64_t> start_ns;  // timed: SOF on the bus clock (= wire_ns for instant frames)
  std::atomic<int64_t> end_ns;    // timed: the bus is free again (after the intermission)
};

// One frame waiting in a port's TX queue of a timed bus.
struct TxEntry {
  std::atomic<uint64_t> header;  // pack_header(), with the sending port's id
  std::atomic<uint64_t> data;
  std::atomic<int64_t> ready_ns;  // bus clock at send(): it may take part in arbitration from then
};

// A port's TX queue (one controller TX buffer, FIFO): written by the owning port (one thread),
// emptied by whichever port currently advances the bus timeline (the scheduler token holder).
struct alignas(64) TxQueue {
  std::atomic<uint32_t> owner;  // sender id of the port holding it, 0: free
  std::atomic<uint64_t> head;   // frames queued (owner)
  std::atomic<uint64_t> tail;   // frames that went on the wire (scheduler)
  TxEntry entries[kTxDepth];
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
  // Timed bus (bitrate != 0). Fixed by the creator; every opener must ask for the same.
  uint32_t bitrate;
  // Held (1) by the one port advancing the timeline: arbitration, publishing, bus_free_ns.
  alignas(64) std::atomic<uint32_t> scheduler;
  std::atomic<int64_t> bus_free_ns;   // end of the last frame's intermission
  std::atomic<uint64_t> wire_frames;  // frames that went on the wire
  std::atomic<int64_t> wire_busy_ns;  // their bus time, intermission included
  vbus::TxQueue tx[vbus::kTxQueues];

  vbus::Slot* slots() noexcept { return reinterpret_cast<vbus::Slot*>(this + 1); }
  static std::size_t bytes(uint32_t capacity) noexcept {
    return sizeof(Ring) + std::size_t{capacity} * sizeof(vbus::Slot);
  }
};
static_assert(alignof(VirtualCanBus::Ring) >= alignof(vbus::Slot));

namespace vbus {
// Writes one frame to the next ticket's slot and wakes sleeping readers. start/end: its time
// on a timed bus (instant: both wire_ns).
void publish(VirtualCanBus::Ring& ring, const CanFrame& f, uint16_t sender, int64_t wire_ns,
             int64_t start_ns, int64_t end_ns) noexcept;
inline void publish(VirtualCanBus::Ring& ring, const CanFrame& f, uint16_t sender,
                    int64_t wire_ns) noexcept {
  publish(ring, f, sender, wire_ns, wire_ns, wire_ns);
}

inline CanFrame unpack(uint64_t header, uint64_t data) noexcept {
  CanFrame f;
  f.id = static_cast<uint32_t>(header & kMaxExtendedId);
  f.extended = ((header >> 29) & 1) != 0;
  f.rtr = ((header >> 30) & 1) != 0;
  f.dlc = static_cast<uint8_t>((header >> 32) & 0xF);
  std::memcpy(f.data.data(), &data, 8);
  return f;
}

// Timed bus: starts every frame whose turn has come by `now` — the bus is free and it wins
// arbitration among the heads of the TX queues ready by then — and publishes it stamped with
// its end of frame. Lazy and exact: run late, it replays the timeline as it would have gone.
// Returns the bus-clock time at which the next queued frame can start (INT64_MAX: none queued;
// `now` + one bit when another port holds the timeline). Instant bus: INT64_MAX.
int64_t advance(VirtualCanBus::Ring& ring, int64_t now) noexcept;

// The arbitration priority of a frame (lower wins): the identifier's bits in wire order, so that
// a standard frame beats an extended one with the same 11 base bits (its RTR/IDE are dominant
// where the extended frame sends SRR/IDE recessive) and a data frame beats a remote frame.
inline uint64_t arbitration_key(uint64_t header) noexcept {
  const uint32_t id = static_cast<uint32_t>(header & kMaxExtendedId);
  const bool ext = ((header >> 29) & 1) != 0;
  const bool rtr = ((header >> 30) & 1) != 0;
  if (!ext) return (uint64_t{id} << 21) | (uint64_t{rtr} << 20);
  // base 11 | SRR (1) | IDE (1) | extension 18 | RTR
  return (uint64_t{id >> 18} << 21) | (1ull << 20) | (1ull << 19) | (uint64_t{id & 0x3FFFF} << 1) |
         uint64_t{rtr};
}
}  // namespace vbus

}  // namespace ds1928::canio
