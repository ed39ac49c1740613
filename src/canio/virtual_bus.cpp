#include "canio/virtual_bus.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <cerrno>
#include <climits>
#include <cstring>
#include <new>
#include <string>

#include "canio/virtual_bus_ring.hpp"

namespace ds1928::canio {

namespace {

using vbus::kLayoutVersion;
using vbus::kMagic;
using Ring = VirtualCanBus::Ring;

int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string shm_object_name(std::string_view name) {
  return "/ds1928-vcan." + std::string(name);
}

bool valid_bus_name(std::string_view name) noexcept {
  if (name.empty() || name.size() > 200) return false;
  for (char c : name)
    if (c == '/' || c == '\0') return false;
  return true;
}

}  // namespace

namespace vbus {

void publish(Ring& ring, const CanFrame& f, uint16_t sender, int64_t wire_ns) noexcept {
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
  s.seq.store(2 * t + 2, std::memory_order_release);
  ring.published.fetch_add(1, std::memory_order_seq_cst);
  if (ring.sleepers.load(std::memory_order_seq_cst) != 0)
    futex(&ring.published, FUTEX_WAKE, INT_MAX, nullptr);
}

}  // namespace vbus

int64_t VirtualCanBus::now_ns() const noexcept {
  return options_.clock ? options_.clock() : monotonic_ns();
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
  bus->ring_->magic = kMagic;
  bus->ring_->version = kLayoutVersion;
  bus->ring_->capacity = cap;
  bus->ring_->ready.store(1, std::memory_order_release);
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
    ring->magic = kMagic;
    ring->version = kLayoutVersion;
    ring->capacity = cap;
    ring->ready.store(1, std::memory_order_release);
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
  return std::unique_ptr<VirtualCanPort>(
      new VirtualCanPort(shared_from_this(), static_cast<uint16_t>(id), std::move(options)));
}

}  // namespace ds1928::canio
