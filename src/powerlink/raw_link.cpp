#include "powerlink/raw_link.hpp"

#include <arpa/inet.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include "core/clock.hpp"

namespace ds1928::powerlink {

namespace {

constexpr uint16_t kEtherTypePowerlink = 0x88AB;
constexpr std::size_t kMinFrame = 60;
constexpr std::size_t kMaxFrame = 1514;
constexpr uint32_t kRingFrameSize = 2048;  // TPACKET_ALIGNed header + 1514 bytes fit
constexpr uint32_t kRingBlockSize = 4096;

class RawLinkCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "powerlink.raw_link"; }
  [[nodiscard]] std::string message(int ev) const override {
    switch (static_cast<RawLinkErrc>(ev)) {
      case RawLinkErrc::kInterfaceNameTooLong:
        return "interface name longer than IFNAMSIZ-1";
      case RawLinkErrc::kNotOpen:
        return "raw link is not open";
        return "link down: interface not up or no carrier";
      case RawLinkErrc::kFrameTooLong:
        return "frame longer than 1514 bytes";
      case RawLinkErrc::kFrameTooShort:
        return "frame shorter than an Ethernet header";
      case RawLinkErrc::kBufferTooSmall:
        return "received frame truncated: buffer too small";
    }
    return "unknown raw link error";
  }
};

[[nodiscard]] std::error_code errno_code(int e = errno) noexcept {
  return {e, std::system_category()};
}

// Link-loss errnos: the interface went down (ENETDOWN) or vanished (ENXIO, ENODEV).
[[nodiscard]] bool is_link_loss(int e) noexcept {
  return e == ENETDOWN || e == ENXIO || e == ENODEV || e == ENETUNREACH;
}

[[nodiscard]] timespec to_timespec(int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  return timespec{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

inline void cpu_relax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield" ::: "memory");
#endif
}

}  // namespace

const std::error_category& raw_link_category() noexcept {
  static const RawLinkCategory category;
  return category;
}

RawLink::~RawLink() {
  close();
}

RawLink::RawLink(RawLink&& other) noexcept {
  move_from(other);
}

RawLink& RawLink::operator=(RawLink&& other) noexcept {
  if (this != &other) {
    close();
    move_from(other);
  }
  return *this;
}

void RawLink::move_from(RawLink& other) noexcept {
  options_ = std::move(other.options_);
  fd_ = std::exchange(other.fd_, -1);
  ifindex_ = other.ifindex_;
  mac_ = other.mac_;
  up_.store(other.up_.load());
  next_carrier_check_ns_ = other.next_carrier_check_ns_;
  ring_ = std::exchange(other.ring_, nullptr);
  ring_bytes_ = std::exchange(other.ring_bytes_, 0);
  ring_frame_size_ = other.ring_frame_size_;
  ring_frame_count_ = other.ring_frame_count_;
  ring_head_ = other.ring_head_;
  stats_ = other.stats_;
}

void RawLink::close() noexcept {
  if (ring_ != nullptr) {
    munmap(ring_, ring_bytes_);
    ring_ = nullptr;
    ring_bytes_ = 0;
  }
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  up_.store(false, std::memory_order_relaxed);
}

std::error_code RawLink::open(const RawLinkOptions& options) {
  close();
  options_ = options;
  if (options_.interface.empty() || options_.interface.size() >= IFNAMSIZ) {
    return RawLinkErrc::kInterfaceNameTooLong;
  }
  // Any failure below closes the half-configured socket again (RAII by the guard).
  struct Guard {
    RawLink* link;
    bool armed = true;
    ~Guard() {
      if (armed) link->close();
    }
  } guard{this};

  fd_ = ::socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, htons(kEtherTypePowerlink));
  if (fd_ < 0) return errno_code();

  ifreq ifr{};
  std::memcpy(ifr.ifr_name, options_.interface.c_str(), options_.interface.size());
  if (ioctl(fd_, SIOCGIFINDEX, &ifr) < 0) return errno_code();
  ifindex_ = ifr.ifr_ifindex;
  if (ioctl(fd_, SIOCGIFHWADDR, &ifr) < 0) return errno_code();
  std::memcpy(mac_.data(), ifr.ifr_hwaddr.sa_data, mac_.size());

  if (options_.qdisc_bypass) {
    const int one = 1;
    if (setsockopt(fd_, SOL_PACKET, PACKET_QDISC_BYPASS, &one, sizeof one) < 0) {
      return errno_code();
    }
  }

  if (options_.rx_mode == RxMode::Ring) {
    const int version = TPACKET_V2;
    if (setsockopt(fd_, SOL_PACKET, PACKET_VERSION, &version, sizeof version) < 0) {
      return errno_code();
    }
    uint32_t frames = std::max<uint32_t>(options_.ring_frames, 8);
    frames = (frames + 1) & ~1u;  // two frames per block
    tpacket_req req{};
    req.tp_block_size = kRingBlockSize;
    req.tp_frame_size = kRingFrameSize;
    req.tp_block_nr = frames / (kRingBlockSize / kRingFrameSize);
    req.tp_frame_nr = frames;
    if (setsockopt(fd_, SOL_PACKET, PACKET_RX_RING, &req, sizeof req) < 0) return errno_code();
    ring_bytes_ = static_cast<std::size_t>(req.tp_block_size) * req.tp_block_nr;
    void* map = mmap(nullptr, ring_bytes_, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_LOCKED, fd_, 0);
    if (map == MAP_FAILED) {
      // MAP_LOCKED may be refused (RLIMIT_MEMLOCK); an unlocked ring still works.
      map = mmap(nullptr, ring_bytes_, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, 0);
    }
    if (map == MAP_FAILED) {
      ring_bytes_ = 0;
      return errno_code();
    }
    ring_ = static_cast<uint8_t*>(map);
    ring_frame_size_ = kRingFrameSize;
    ring_frame_count_ = frames;
    ring_head_ = 0;
  }

  // Binding last: frames are queued only from here on, and the ring already exists.
  sockaddr_ll addr{};
  addr.sll_family = AF_PACKET;
  addr.sll_protocol = htons(kEtherTypePowerlink);
  addr.sll_ifindex = ifindex_;
  if (bind(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) < 0) return errno_code();

  // A NIC's hardware filter drops multicast it was not told about: SoC ..:01, PRes ..:02,
  // SoA ..:03, ASnd ..:04.
  for (uint8_t last = 1; last <= 4; ++last) {
    packet_mreq mreq{};
    mreq.mr_ifindex = ifindex_;
    mreq.mr_type = PACKET_MR_MULTICAST;
    mreq.mr_alen = 6;
    const uint8_t group[6] = {0x01, 0x11, 0x1E, 0x00, 0x00, last};
    std::memcpy(mreq.mr_address, group, sizeof group);
    if (setsockopt(fd_, SOL_PACKET, PACKET_ADD_MEMBERSHIP, &mreq, sizeof mreq) < 0) {
      return errno_code();
    }
  }
  if (options_.promiscuous) {
    packet_mreq mreq{};
    mreq.mr_ifindex = ifindex_;
    mreq.mr_type = PACKET_MR_PROMISC;
    if (setsockopt(fd_, SOL_PACKET, PACKET_ADD_MEMBERSHIP, &mreq, sizeof mreq) < 0) {
      return errno_code();
    }
  }
  if (options_.rx_mode != RxMode::Ring) {
    // Frames that sat in the socket before bind() completed may be of another protocol.
    uint8_t scratch[kMaxFrame];
    while (recv(fd_, scratch, sizeof scratch, MSG_DONTWAIT) > 0) {
    }
  }
  guard.armed = false;
  stats_ = RawLinkStats{};
  refresh_link_state();
  next_carrier_check_ns_ = rt::now_ns() + options_.carrier_check_interval_ns;
  return {};
}

void RawLink::set_up(bool up) const noexcept {
  const bool was = up_.exchange(up, std::memory_order_relaxed);
  if (was && !up) ++stats_.link_losses;
}

bool RawLink::link_up() const noexcept {
  if (up_.load(std::memory_order_relaxed)) return true;
  const int64_t now = rt::now_ns();
  if (fd_ >= 0 && now >= next_carrier_check_ns_) {
    refresh_link_state();
    next_carrier_check_ns_ = now + options_.carrier_check_interval_ns;
  }
  return up_.load(std::memory_order_relaxed);
}

void RawLink::refresh_link_state() const noexcept {
  if (fd_ < 0) {
    set_up(false);
    return;
  }
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, options_.interface.c_str(), options_.interface.size());
  if (ioctl(fd_, SIOCGIFFLAGS, &ifr) < 0) {
    set_up(false);
    return;
  }
  const auto flags = static_cast<unsigned>(ifr.ifr_flags);
  set_up((flags & IFF_UP) != 0 && (flags & IFF_RUNNING) != 0);
}

std::error_code RawLink::send(std::span<const uint8_t> frame) noexcept {
  if (fd_ < 0) return RawLinkErrc::kNotOpen;
  if (frame.size() > kMaxFrame) return RawLinkErrc::kFrameTooLong;
  if (frame.size() < 14) return RawLinkErrc::kFrameTooShort;

  // A veth or NIC without carrier swallows frames without an error, so the interface flags are
  // the only witness of a lost carrier. They are not a reason to refuse sending: the kernel
  // publishes carrier changes late (linkwatch, up to 1 s), frames may flow before IFF_RUNNING.
  const int64_t now = rt::now_ns();
  if (now >= next_carrier_check_ns_) {
    refresh_link_state();
    next_carrier_check_ns_ = now + options_.carrier_check_interval_ns;
  }

  const uint8_t* data = frame.data();
  std::size_t size = frame.size();
  uint8_t padded[kMinFrame];
  if (size < kMinFrame) {
    std::memcpy(padded, data, size);
    std::memset(padded + size, 0, kMinFrame - size);
    data = padded;
    size = kMinFrame;
  }
  for (;;) {
    const ssize_t n = ::send(fd_, data, size, MSG_DONTWAIT);
    if (n == static_cast<ssize_t>(size)) {
      ++stats_.tx_frames;
      return {};
    }
    if (n < 0 && errno == EINTR) continue;
    ++stats_.tx_errors;
    if (n < 0) {
      const int e = errno;
      if (is_link_loss(e)) set_up(false);
      return errno_code(e);
    }
    return errno_code(EIO);
  }
}

bool RawLink::ring_ready() const noexcept {
  const auto* hdr = reinterpret_cast<const tpacket2_hdr*>(
      ring_ + static_cast<std::size_t>(ring_head_) * ring_frame_size_);
  return (__atomic_load_n(&hdr->tp_status, __ATOMIC_ACQUIRE) & TP_STATUS_USER) != 0;
}

Received RawLink::receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept {
  if (fd_ < 0) return Received{0, 0, make_error_code(RawLinkErrc::kNotOpen)};
  switch (options_.rx_mode) {
    case RxMode::Ring:
      return receive_ring(buffer, deadline_ns);
    case RxMode::BusyPoll:
      return receive_socket(buffer, deadline_ns, false);
    case RxMode::Blocking:
      return receive_socket(buffer, deadline_ns, true);
  }
  return Received{0, 0, make_error_code(RawLinkErrc::kNotOpen)};
}

Received RawLink::receive_ring(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept {
  // Polls the head slot's status word: no syscall while waiting, and the check costs a cache
  // line that the kernel writes when it fills the slot.
  auto* hdr = reinterpret_cast<tpacket2_hdr*>(ring_ + static_cast<std::size_t>(ring_head_) *
                                                          ring_frame_size_);
  auto ready = [hdr] {
    return (__atomic_load_n(&hdr->tp_status, __ATOMIC_ACQUIRE) & TP_STATUS_USER) != 0;
  };
  if (!ready()) {
    const int64_t spin_ns = options_.ring_spin_ns;
    int64_t spin_until = deadline_ns;
    if (spin_ns >= 0) spin_until = spin_ns == 0 ? 0 : std::min(deadline_ns, rt::now_ns() + spin_ns);
    uint32_t spins = 0;
    while (!ready()) {
      // Reading the clock every poll would dominate the loop; every 16th is fine-grained enough.
      if (spin_until != 0 && ((++spins & 15u) != 0 || rt::now_ns() < spin_until)) {
        cpu_relax();
        continue;
      }
      // Spin budget spent: the rest of the wait sleeps in the kernel, which wakes this thread
      // when the frame lands (poll on a ring socket reports the head slot's status).
      const int64_t now = rt::now_ns();
      if (now >= deadline_ns) {
        if (ready()) break;
        return Received{};
      }
      spin_until = 0;
      pollfd pfd{fd_, POLLIN, 0};
      const timespec timeout = to_timespec(deadline_ns - now);
      const int r = ppoll(&pfd, 1, &timeout, nullptr);
      if (r < 0 && errno != EINTR) return Received{0, 0, errno_code(errno)};
      if (r > 0 && (pfd.revents & POLLERR) != 0 && !ready()) {
        int err = 0;
        socklen_t len = sizeof err;
        getsockopt(fd_, SOL_SOCKET, SO_ERROR, &err, &len);
        if (err != 0) {
          if (is_link_loss(err)) set_up(false);
          return Received{0, 0, errno_code(err)};
        }
      }
    }
  }
  // The kernel stamped the frame when it arrived (CLOCK_REALTIME); moved to CLOCK_MONOTONIC it
  // is the arrival instant even when this thread was late to look.
  const int64_t real_ns = rt::realtime_ns();
  const int64_t mono = rt::now_ns();
  const int64_t stamp_ns = static_cast<int64_t>(hdr->tp_sec) * 1'000'000'000 + hdr->tp_nsec;
  int64_t rx_time = stamp_ns != 0 ? stamp_ns - (real_ns - mono) : mono;
  if (rx_time > mono || rx_time < mono - 1'000'000'000) rx_time = mono;  // clock step
  const std::size_t len = hdr->tp_snaplen;
  const uint8_t* data = reinterpret_cast<const uint8_t*>(hdr) + hdr->tp_mac;
  const std::size_t copied = std::min(len, buffer.size());
  std::memcpy(buffer.data(), data, copied);
  __atomic_store_n(&hdr->tp_status, TP_STATUS_KERNEL, __ATOMIC_RELEASE);
  ring_head_ = (ring_head_ + 1) % ring_frame_count_;
  ++stats_.rx_frames;
  if (copied < len) {
    ++stats_.rx_truncated;
    return Received{copied, rx_time, make_error_code(RawLinkErrc::kBufferTooSmall)};
  }
  return Received{copied, rx_time, {}};
}

Received RawLink::receive_socket(std::span<uint8_t> buffer, int64_t deadline_ns,
                                 bool block) noexcept {
  for (;;) {
    const ssize_t n = recv(fd_, buffer.data(), buffer.size(), MSG_DONTWAIT | MSG_TRUNC);
    if (n >= 0) {
      ++stats_.rx_frames;
      if (static_cast<std::size_t>(n) > buffer.size()) {
        ++stats_.rx_truncated;
        return Received{buffer.size(), rt::now_ns(), make_error_code(RawLinkErrc::kBufferTooSmall)};
      }
      return Received{static_cast<std::size_t>(n), rt::now_ns(), {}};
    }
    const int e = errno;
    if (e == EINTR) continue;
    if (e != EAGAIN && e != EWOULDBLOCK) {
      if (is_link_loss(e)) set_up(false);
      return Received{0, 0, errno_code(e)};
    }
    const int64_t now = rt::now_ns();
    if (now >= deadline_ns) return Received{};
    if (block) {
      pollfd pfd{fd_, POLLIN, 0};
      const timespec timeout = to_timespec(deadline_ns - now);
      const int r = ppoll(&pfd, 1, &timeout, nullptr);
      if (r == 0) return Received{};
      if (r > 0 && (pfd.revents & POLLERR) != 0 && (pfd.revents & POLLIN) == 0) {
        int err = 0;
        socklen_t len = sizeof err;
        getsockopt(fd_, SOL_SOCKET, SO_ERROR, &err, &len);
        if (err != 0) {
          if (is_link_loss(err)) set_up(false);
          return Received{0, 0, errno_code(err)};
        }
      }
    } else {
      cpu_relax();
    }
  }
}

bool RawLink::wait_readable(int64_t deadline_ns) noexcept {
  if (fd_ < 0) return false;
  for (;;) {
    if (ring_ != nullptr && ring_ready()) return true;
    const int64_t now = rt::now_ns();
    if (now >= deadline_ns) return false;
    pollfd pfd{fd_, POLLIN, 0};
    const timespec timeout = to_timespec(deadline_ns - now);
    const int r = ppoll(&pfd, 1, &timeout, nullptr);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    if ((pfd.revents & POLLERR) != 0) {
      int err = 0;
      socklen_t len = sizeof err;
      getsockopt(fd_, SOL_SOCKET, SO_ERROR, &err, &len);
      if (is_link_loss(err)) set_up(false);
    }
    if ((pfd.revents & POLLIN) != 0) return true;
    if ((pfd.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0) return false;
  }
}

void RawLink::read_kernel_drops() noexcept {
  if (fd_ < 0) return;
  tpacket_stats st{};
  socklen_t len = sizeof st;
  if (getsockopt(fd_, SOL_PACKET, PACKET_STATISTICS, &st, &len) == 0) {
    stats_.kernel_drops += st.tp_drops;
  }
}

}  // namespace ds1928::powerlink
