#include "can/virtual_bus.hpp"

#include <fcntl.h>
#include <pwd.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <array>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>

#include "can/bit_budget.hpp"
#include "can/virtual_bus_ring.hpp"
#include "core/clock.hpp"

namespace ds1928::canio {

namespace {

using vbus::kLayoutVersion;
using vbus::kMagic;
using Ring = VirtualCanBus::Ring;

std::string shm_object_name(std::string_view name) {
  return "/ds1928-vcan." + std::string(name);
}

// "The shared bus runs at X bit/s, this process asked for Y": an error_code cannot carry the
// two numbers, so the code's value indexes a small table of recent mismatches (opening a bus is
// rare; the 16 latest are kept).
std::array<std::atomic<uint64_t>, 16> g_bitrate_mismatches{};
std::atomic<uint32_t> g_next_mismatch{0};

class BitrateMismatchCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "virtual CAN bus bit rate"; }
  std::string message(int ev) const override {
    if (ev < 1 || ev > static_cast<int>(g_bitrate_mismatches.size()))
      return "the shared virtual CAN bus runs at another bit rate";
    const uint64_t v = g_bitrate_mismatches[static_cast<std::size_t>(ev - 1)].load();
    auto rate = [](uint32_t r) {
      return r == 0 ? std::string("0 bit/s (instant, no bit timing)")
                    : std::to_string(r) + " bit/s";
    };
    return "the shared virtual CAN bus runs at " + rate(static_cast<uint32_t>(v >> 32)) +
           ", this process opens it at " + rate(static_cast<uint32_t>(v)) +
           ": give both sides the same canio.bitrate";
  }
};

std::error_code bitrate_mismatch(uint32_t bus, uint32_t wanted) noexcept {
  static const BitrateMismatchCategory category;
  const uint32_t i = g_next_mismatch.fetch_add(1) % g_bitrate_mismatches.size();
  g_bitrate_mismatches[i].store((uint64_t{bus} << 32) | wanted);
  return {static_cast<int>(i) + 1, category};
}

void init_ring(Ring& ring, uint32_t capacity, uint32_t bitrate) noexcept {
  ring.magic = kMagic;
  ring.version = kLayoutVersion;
  ring.capacity = capacity;
  ring.bitrate = bitrate;
  ring.ready.store(1, std::memory_order_release);
}

bool valid_bus_name(std::string_view name) noexcept {
  if (name.empty() || name.size() > 200) return false;
  for (char c : name)
    if (c == '/' || c == '\0') return false;
  return true;
}

}  // namespace

namespace vbus {

void publish(Ring& ring, const CanFrame& f, uint16_t sender, int64_t wire_ns, int64_t start_ns,
             int64_t end_ns) noexcept {
  const uint64_t t = ring.head.fetch_add(1, std::memory_order_acq_rel);
  const uint64_t mask = ring.capacity - 1;
  vbus::Slot& s = ring.slots()[t & mask];
  // The slot's previous round (ticket t - capacity) must be complete before it is reused; a
  // writer that far behind is only possible when a process died mid-write, so wait briefly and
  // then take the slot anyway.
  if (t >= ring.capacity) {
    const uint64_t previous = 2 * (t - ring.capacity) + 2;
    for (int spin = 0; spin < 10'000 && s.seq.load(std::memory_order_acquire) < previous; ++spin) {
    }
  }
  s.seq.store(2 * t + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  s.header.store(pack_header(f, sender), std::memory_order_relaxed);
  s.data.store(pack_data(f), std::memory_order_relaxed);
  s.wire_ns.store(wire_ns, std::memory_order_relaxed);
  s.start_ns.store(start_ns, std::memory_order_relaxed);
  s.end_ns.store(end_ns, std::memory_order_relaxed);
  s.seq.store(2 * t + 2, std::memory_order_release);
  ring.published.fetch_add(1, std::memory_order_seq_cst);
  if (ring.sleepers.load(std::memory_order_seq_cst) != 0)
    futex(&ring.published, FUTEX_WAKE, INT_MAX, nullptr);
}

int64_t advance(Ring& ring, int64_t now) noexcept {
  const uint32_t bitrate = ring.bitrate;
  if (bitrate == 0) return INT64_MAX;
  uint32_t free_token = 0;
  if (!ring.scheduler.compare_exchange_strong(free_token, 1, std::memory_order_acquire,
                                              std::memory_order_relaxed)) {
    // Another port is advancing the timeline right now; look again one bit later.
    return now + bits_to_ns(1, bitrate);
  }
  int64_t next = INT64_MAX;
  for (;;) {
    const int64_t bus_free = ring.bus_free_ns.load(std::memory_order_relaxed);
    // The head of every TX queue: the earliest ready one says when the bus is next contended.
    int64_t earliest = INT64_MAX;
    for (TxQueue& q : ring.tx) {
      const uint64_t tail = q.tail.load(std::memory_order_relaxed);
      if (q.head.load(std::memory_order_acquire) == tail) continue;
      const int64_t ready = q.entries[tail % kTxDepth].ready_ns.load(std::memory_order_relaxed);
      if (ready < earliest) earliest = ready;
    }
    if (earliest == INT64_MAX) break;
    const int64_t start = earliest > bus_free ? earliest : bus_free;
    if (start > now) {
      next = start;
      break;
    }
    // Arbitration at `start` among the heads ready by then: lowest priority key wins; equal
    // keys (two ports sending one identifier) go by queue index — no bit-level collision model.
    TxQueue* winner = nullptr;
    uint64_t winner_header = 0, winner_key = UINT64_MAX;
    for (TxQueue& q : ring.tx) {
      const uint64_t tail = q.tail.load(std::memory_order_relaxed);
      if (q.head.load(std::memory_order_acquire) == tail) continue;
      const TxEntry& e = q.entries[tail % kTxDepth];
      if (e.ready_ns.load(std::memory_order_relaxed) > start) continue;
      const uint64_t header = e.header.load(std::memory_order_relaxed);
      const uint64_t key = arbitration_key(header);
      if (key < winner_key) {
        winner_key = key;
        winner_header = header;
        winner = &q;
      }
    }
    if (winner == nullptr) break;  // cannot happen: the earliest head is ready by `start`
    const uint64_t tail = winner->tail.load(std::memory_order_relaxed);
    const CanFrame f = unpack(
        winner_header, winner->entries[tail % kTxDepth].data.load(std::memory_order_relaxed));
    const uint32_t bits = frame_wire_bits(f);
    const int64_t end = start + bits_to_ns(bits, bitrate);
    // Receivers take the frame at the end of its EOF; the intermission keeps the bus busy.
    const int64_t eof = start + bits_to_ns(bits - kIntermissionBits, bitrate);
    winner->tail.store(tail + 1, std::memory_order_release);  // the sender's TX slot is free
    ring.bus_free_ns.store(end, std::memory_order_relaxed);
    ring.wire_frames.fetch_add(1, std::memory_order_relaxed);
    ring.wire_busy_ns.fetch_add(end - start, std::memory_order_relaxed);
    publish(ring, f, static_cast<uint16_t>(winner_header >> 48), eof, start, end);
  }
  ring.scheduler.store(0, std::memory_order_release);
  return next;
}

}  // namespace vbus

VirtualBusOptions virtual_bus_options(uint32_t bitrate) {
  VirtualBusOptions o;
  const char* instant = std::getenv("DS1928_VIRTUAL_BUS_INSTANT");
  o.bitrate = instant != nullptr && std::string_view(instant) == "1" ? 0 : bitrate;
  return o;
}

int64_t VirtualCanBus::now_ns() const noexcept {
  return options_.clock ? options_.clock() : rt::now_ns();
}

std::shared_ptr<VirtualCanBus> VirtualCanBus::create_local(VirtualBusOptions options) {
  uint32_t cap = options.ring_frames < 2 ? 2 : options.ring_frames;
  if ((cap & (cap - 1)) != 0) cap = 1u << (32 - __builtin_clz(cap));
  std::shared_ptr<VirtualCanBus> bus(new VirtualCanBus());
  bus->options_ = std::move(options);
  bus->options_.ring_frames = cap;
  bus->mapped_bytes_ = Ring::bytes(cap);
  void* mem = ::operator new (bus->mapped_bytes_, std::align_val_t{64});
  std::memset(mem, 0, bus->mapped_bytes_);
  bus->ring_ = static_cast<Ring*>(mem);
  init_ring(*bus->ring_, cap, bus->options_.bitrate);
  return bus;
}

Result<std::shared_ptr<VirtualCanBus>> VirtualCanBus::open_shared(std::string_view name,
                                                                  VirtualBusOptions options,
                                                                  bool unlink_on_close) {
  if (!valid_bus_name(name)) return CanError::kInterfaceNameInvalid;
  uint32_t cap = options.ring_frames < 2 ? 2 : options.ring_frames;
  if ((cap & (cap - 1)) != 0) cap = 1u << (32 - __builtin_clz(cap));
  const std::string shm = shm_object_name(name);
  const std::size_t bytes = Ring::bytes(cap);
  bool creator = true;
  int fd = shm_open(shm.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0 && errno == EEXIST) {
    creator = false;
    fd = shm_open(shm.c_str(), O_RDWR | O_CLOEXEC, 0600);
  }
  if (fd < 0) return std::error_code(errno, std::system_category());
  if (creator && ftruncate(fd, static_cast<off_t>(bytes)) != 0) {
    const int err = errno;
    close(fd);
    shm_unlink(shm.c_str());
    return std::error_code(err, std::system_category());
  }
  if (!creator) {
    // The creator may still be sizing it: wait (bounded) for the size, then for `ready`.
    struct stat st {};
    for (int i = 0; i < 1000; ++i) {
      if (fstat(fd, &st) == 0 && static_cast<std::size_t>(st.st_size) >= sizeof(Ring)) break;
      timespec pause{0, 1'000'000};
      nanosleep(&pause, nullptr);
    }
    if (static_cast<std::size_t>(st.st_size) != bytes) {
      close(fd);
      return CanError::kVirtualBusMismatch;
    }
  }
  void* mem = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int map_err = errno;
  close(fd);
  if (mem == MAP_FAILED) return std::error_code(map_err, std::system_category());
  auto* ring = static_cast<Ring*>(mem);
  if (creator) {
    init_ring(*ring, cap, options.bitrate);
  } else {
    for (int i = 0; i < 1000 && ring->ready.load(std::memory_order_acquire) == 0; ++i) {
      timespec pause{0, 1'000'000};
      nanosleep(&pause, nullptr);
    }
    if (ring->ready.load(std::memory_order_acquire) == 0 || ring->magic != kMagic ||
        ring->version != kLayoutVersion || ring->capacity != cap) {
      munmap(mem, bytes);
      return CanError::kVirtualBusMismatch;
    }
    if (ring->bitrate != options.bitrate) {
      const uint32_t have = ring->bitrate;
      munmap(mem, bytes);
      return bitrate_mismatch(have, options.bitrate);
    }
  }
  std::shared_ptr<VirtualCanBus> bus(new VirtualCanBus());
  bus->options_ = std::move(options);
  bus->options_.ring_frames = cap;
  bus->ring_ = ring;
  bus->mapped_bytes_ = bytes;
  bus->shared_ = true;
  bus->shm_name_ = shm;
  bus->unlink_on_close_ = unlink_on_close;
  return bus;
}

std::error_code VirtualCanBus::remove_shared(std::string_view name) noexcept {
  if (!valid_bus_name(name)) return CanError::kInterfaceNameInvalid;
  std::string shm;
  try {
    shm = shm_object_name(name);
  } catch (...) {
    return std::make_error_code(std::errc::not_enough_memory);
  }
  if (shm_unlink(shm.c_str()) != 0 && errno != ENOENT) return {errno, std::system_category()};
  return {};
}

std::string VirtualCanBus::open_error_text(std::string_view name, std::error_code ec) {
  std::string text = ec.message();
  if (ec != std::error_code(EACCES, std::system_category()) || !valid_bus_name(name)) return text;
  const std::string file = "/dev/shm" + shm_object_name(name);
  struct stat st {};
  if (::stat(file.c_str(), &st) != 0) return text;
  std::string owner = "uid " + std::to_string(st.st_uid);
  if (const passwd* pw = ::getpwuid(st.st_uid)) owner += " (" + std::string(pw->pw_name) + ")";
  char mode[8];
  std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
  return text + ": " + file + " belongs to " + owner + ", mode " + mode +
         " (a bus another user's run left behind): remove it (rm " + file + ") or run as that user";
}

VirtualCanBus::~VirtualCanBus() {
  if (ring_ == nullptr) return;
  if (shared_) {
    munmap(ring_, mapped_bytes_);
    if (unlink_on_close_) shm_unlink(shm_name_.c_str());
  } else {
    ::operator delete (static_cast<void*>(ring_), std::align_val_t{64});
  }
}

Result<std::unique_ptr<VirtualCanPort>> VirtualCanBus::open_port(VirtualPortOptions options) {
  // Sender ids start at 1 and wrap at 16 bits; two live ports sharing one would hide each
  // other's frames, which takes 65536 ports opened on one bus.
  uint32_t id = ring_->next_port.fetch_add(1, std::memory_order_relaxed) + 1;
  if ((id & 0xFFFF) == 0) id = ring_->next_port.fetch_add(1, std::memory_order_relaxed) + 1;
  int tx_queue = -1;
  if (timed()) {
    // A free TX queue that has drained (a closed port's last frames still go out first).
    for (uint32_t i = 0; i < vbus::kTxQueues && tx_queue < 0; ++i) {
      vbus::TxQueue& q = ring_->tx[i];
      uint32_t free_owner = 0;
      if (q.head.load(std::memory_order_acquire) != q.tail.load(std::memory_order_acquire))
        continue;
      if (q.owner.compare_exchange_strong(free_owner, id & 0xFFFF, std::memory_order_acq_rel))
        tx_queue = static_cast<int>(i);
    }
    if (tx_queue < 0) return std::make_error_code(std::errc::no_buffer_space);
  }
  auto port = std::unique_ptr<VirtualCanPort>(
      new VirtualCanPort(shared_from_this(), static_cast<uint16_t>(id), std::move(options)));
  port->tx_queue_ = tx_queue;
  return port;
}

uint32_t VirtualCanBus::bitrate() const noexcept {
  return ring_->bitrate;
}

int64_t VirtualCanBus::wire_time_ns(const CanFrame& frame) const noexcept {
  return bits_to_ns(frame_wire_bits(frame), ring_->bitrate);
}

WireTotals VirtualCanBus::wire_totals() noexcept {
  (void)vbus::advance(*ring_, now_ns());
  WireTotals t;
  t.frames = ring_->wire_frames.load(std::memory_order_relaxed);
  t.busy_ns = ring_->wire_busy_ns.load(std::memory_order_relaxed);
  t.bus_free_ns = ring_->bus_free_ns.load(std::memory_order_relaxed);
  return t;
}

BusLoad VirtualCanBus::load(int64_t from_ns, int64_t to_ns) noexcept {
  (void)vbus::advance(*ring_, now_ns());
  BusLoad l;
  l.from_ns = from_ns;
  l.to_ns = to_ns;
  if (to_ns <= from_ns) return l;
  // The frames still in the ring (the last `capacity` ones), newest first; each counts with the
  // part of its bus time inside the window.
  const uint64_t head = ring_->head.load(std::memory_order_acquire);
  const uint64_t mask = ring_->capacity - 1;
  for (uint64_t t = head; t != 0 && head - t < ring_->capacity; --t) {
    vbus::Slot& s = ring_->slots()[(t - 1) & mask];
    const uint64_t want = 2 * (t - 1) + 2;
    if (s.seq.load(std::memory_order_acquire) != want) continue;
    const uint64_t header = s.header.load(std::memory_order_relaxed);
    const int64_t start = s.start_ns.load(std::memory_order_relaxed);
    const int64_t end = s.end_ns.load(std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_acquire);
    if (s.seq.load(std::memory_order_relaxed) != want) continue;
    if (((header >> 31) & 1) != 0 || end <= start) continue;  // error broadcasts take no time
    if (end <= from_ns) break;                                // frames are on the ring in bus order
    const int64_t a = start > from_ns ? start : from_ns;
    const int64_t b = end < to_ns ? end : to_ns;
    if (b > a) {
      l.busy_ns += b - a;
      ++l.frames;
    }
  }
  l.load = static_cast<double>(l.busy_ns) / static_cast<double>(to_ns - from_ns);
  return l;
}

}  // namespace ds1928::canio
