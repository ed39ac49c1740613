#include "can/socketcan_port.hpp"

#include <linux/can.h>
#include <linux/can/raw.h>
#include <linux/errqueue.h>
#include <linux/net_tstamp.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <time.h>

#include <array>
#include <cerrno>
#include <cstring>

#include "can/can_port_counters.hpp"
#include "core/clock.hpp"

namespace ds1928::canio {
namespace {

// Frames taken per recvmmsg: a cycle's inputs for 8 modules plus error frames fit in one call.
constexpr std::size_t kBatch = 32;
// SCM_TIMESTAMPING (three timespecs) or SCM_TIMESTAMPNS, plus SO_RXQ_OVFL's counter.
constexpr std::size_t kControlBytes =
    CMSG_SPACE(sizeof(scm_timestamping)) + CMSG_SPACE(sizeof(uint32_t)) + 64;

int64_t ns_of(const timespec& ts) noexcept {
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::error_code errno_code(int e) noexcept {
  return {e, std::system_category()};
}

}  // namespace

struct SocketCanPort::Impl {
  std::array<can_frame, kBatch> frames{};
  std::array<iovec, kBatch> iov{};
  std::array<mmsghdr, kBatch> msgs{};
  alignas(cmsghdr) std::array<std::array<uint8_t, kControlBytes>, kBatch> control{};

  std::atomic<uint8_t> state{static_cast<uint8_t>(CanState::Unknown)};
  AtomicCanPortCounters counters;

  Impl() {
    for (std::size_t i = 0; i < kBatch; ++i) {
      iov[i].iov_base = &frames[i];
      iov[i].iov_len = sizeof(can_frame);
    }
  }
  void arm() noexcept {
    // recvmmsg overwrites msg_controllen / msg_flags: restore before every call.
    for (std::size_t i = 0; i < kBatch; ++i) {
      msghdr& h = msgs[i].msg_hdr;
      h = msghdr{};
      h.msg_iov = &iov[i];
      h.msg_iovlen = 1;
      h.msg_control = control[i].data();
      h.msg_controllen = control[i].size();
    }
  }
  void set_state(CanState s) noexcept {
    state.store(static_cast<uint8_t>(s), std::memory_order_release);
  }
  CanState get_state() const noexcept {
    return static_cast<CanState>(state.load(std::memory_order_acquire));
  }
};

std::error_code probe_af_can() noexcept {
  UniqueFd fd(socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW));
  if (!fd.valid()) return errno_code(errno);
  return {};
}

SocketCanOpen SocketCanPort::open(const SocketCanOptions& options) {
  SocketCanOpen result;
  const std::string& name = options.interface;
  // AF_CAN first: without it no CAN interface can exist, and "no interface" would mislead.
  UniqueFd fd(socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW));
  if (!fd.valid()) {
    const int e = errno;
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT) {
      result.error = make_error_code(CanError::kNoCanSupport);
      result.message = "this kernel has no AF_CAN (socket(AF_CAN, SOCK_RAW, CAN_RAW): " +
                       std::string(std::strerror(e)) +
                       "): load the CAN modules (modprobe can-raw) or use a kernel with "
                       "CONFIG_CAN; the virtual bus needs neither";
    } else {
      result.error = errno_code(e);
      result.message = "socket(AF_CAN, SOCK_RAW, CAN_RAW) failed: " + std::string(std::strerror(e));
    }
    return result;
  }
  auto link = query_can_link(name);
  if (!link) {
    result.error = link.error();
    result.message = describe_link_error(name, link.error());
    return result;
  }
  auto verdict = check_can_link(name, *link, options.expected_bitrate, options.require_up);
  if (verdict.error) {
    result.error = verdict.error;
    result.message = std::move(verdict.message);
    return result;
  }
  auto fail = [&](const char* what) {
    const int e = errno;
    result.error = errno_code(e);
    result.message = "CAN interface '" + name + "': " + what + ": " + std::strerror(e);
    return std::move(result);
  };
  const int on = 1;
  // Kernel RX stamps in the same recvmmsg as the frame; SO_TIMESTAMPNS where the richer option
  // is refused.
  const int ts_flags = SOF_TIMESTAMPING_RX_SOFTWARE | SOF_TIMESTAMPING_SOFTWARE;
  if (setsockopt(fd.get(), SOL_SOCKET, SO_TIMESTAMPING, &ts_flags, sizeof ts_flags) != 0) {
    if (setsockopt(fd.get(), SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0)
      return fail("setsockopt(SO_TIMESTAMPNS)");
  }
  if (setsockopt(fd.get(), SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on) != 0)
    return fail("setsockopt(SO_RXQ_OVFL)");
  if (options.receive_buffer_bytes > 0 &&
      setsockopt(fd.get(), SOL_SOCKET, SO_RCVBUF, &options.receive_buffer_bytes,
                 sizeof options.receive_buffer_bytes) != 0)
    return fail("setsockopt(SO_RCVBUF)");
  const int own = options.receive_own ? 1 : 0;
  if (setsockopt(fd.get(), SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &own, sizeof own) != 0)
    return fail("setsockopt(CAN_RAW_RECV_OWN_MSGS)");
  const can_err_mask_t mask = options.error_mask & err_class::kAll;
  if (setsockopt(fd.get(), SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof mask) != 0)
    return fail("setsockopt(CAN_RAW_ERR_FILTER)");
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = link->info.ifindex;
  if (bind(fd.get(), reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) return fail("bind");
  result.port.reset(new SocketCanPort(options, std::move(fd)));
  result.port->impl_->set_state(link->info.state);
  return result;
}

SocketCanPort::SocketCanPort(SocketCanOptions options, UniqueFd fd)
    : options_(std::move(options)), fd_(std::move(fd)), impl_(std::make_unique<Impl>()) {}

SocketCanPort::~SocketCanPort() = default;

SendResult SocketCanPort::send(const CanFrame& frame) noexcept {
  Impl& p = *impl_;
  if (!is_sendable(frame)) {
    bump(p.counters.tx_invalid);
    return {SendStatus::InvalidFrame, EINVAL};
  }
  can_frame cf{};
  cf.can_id = frame.extended ? (frame.id & CAN_EFF_MASK) | CAN_EFF_FLAG : frame.id & CAN_SFF_MASK;
  if (frame.rtr) cf.can_id |= CAN_RTR_FLAG;
  cf.len = frame.dlc;
  if (!frame.rtr) std::memcpy(cf.data, frame.data.data(), frame.dlc);
  const ssize_t n = ::send(fd_.get(), &cf, sizeof cf, MSG_DONTWAIT);
  if (n == static_cast<ssize_t>(sizeof cf)) {
    bump(p.counters.tx_frames);
    return {};
  }
  const int e = n < 0 ? errno : EIO;
  switch (e) {
    case ENOBUFS:
    case EAGAIN:
      // A controller that is bus-off stops its queue: the queue fills because of it.
      if (p.get_state() == CanState::BusOff) {
        bump(p.counters.tx_bus_off);
        return {SendStatus::BusOff, e};
      }
      bump(p.counters.tx_queue_full);
      return {SendStatus::QueueFull, e};
    case ENETDOWN:
    case ENXIO:
    case ENODEV:
      bump(p.counters.tx_interface_down);
      p.set_state(CanState::Down);
      return {SendStatus::InterfaceDown, e};
    default:
      bump(p.counters.tx_errors);
      return {SendStatus::Failed, e};
  }
}

ReceiveResult SocketCanPort::receive(std::span<CanFrame> out, int64_t deadline_ns) noexcept {
  Impl& p = *impl_;
  if (out.empty()) return {};
  for (;;) {
    const unsigned want = static_cast<unsigned>(out.size() < kBatch ? out.size() : kBatch);
    p.arm();
    const int n = recvmmsg(fd_.get(), p.msgs.data(), want, MSG_DONTWAIT, nullptr);
    if (n > 0) {
      // One REALTIME→MONOTONIC offset per batch: the frames arrived within microseconds.
      // REALTIME is read first: a delay between the two reads then moves a stamp later, never
      // earlier, and never past `mono` — so a stamp stays between the send and this read. (The
      // other order put a stamp before its own send when the thread was preempted in between.)
      const int64_t realtime = rt::realtime_ns();
      const int64_t mono = rt::now_ns();
      const int64_t offset = realtime - mono;
      std::size_t count = 0;
      for (int i = 0; i < n; ++i) {
        const msghdr& h = p.msgs[i].msg_hdr;
        if (p.msgs[i].msg_len < sizeof(can_frame)) continue;  // CAN FD is off: never happens
        const can_frame& cf = p.frames[i];
        CanFrame f;
        f.error = (cf.can_id & CAN_ERR_FLAG) != 0;
        f.extended = !f.error && (cf.can_id & CAN_EFF_FLAG) != 0;
        f.rtr = !f.error && (cf.can_id & CAN_RTR_FLAG) != 0;
        f.id = f.error ? cf.can_id & CAN_ERR_MASK
                       : cf.can_id & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
        f.dlc = cf.len > kMaxDlc ? kMaxDlc : cf.len;
        std::memcpy(f.data.data(), cf.data, 8);
        int64_t stamp = 0;
        for (cmsghdr* c = CMSG_FIRSTHDR(&h); c != nullptr;
             c = CMSG_NXTHDR(const_cast<msghdr*>(&h), c)) {
          if (c->cmsg_level != SOL_SOCKET) continue;
          if (c->cmsg_type == SO_TIMESTAMPING) {
            scm_timestamping ts;
            std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
            stamp = ns_of(ts.ts[0]);  // software stamp
          } else if (c->cmsg_type == SO_TIMESTAMPNS) {
            timespec ts;
            std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
            stamp = ns_of(ts);
          } else if (c->cmsg_type == SO_RXQ_OVFL) {
            uint32_t drops = 0;
            std::memcpy(&drops, CMSG_DATA(c), sizeof drops);
            // The kernel's running total for this socket.
            p.counters.rx_kernel_drops.store(drops, std::memory_order_relaxed);
          }
        }
        if (stamp != 0) {
          f.rx_time_ns = stamp - offset;
          f.rx_clock = RxClock::KernelSoftware;
          // A clock step between stamp and read would put the frame in the future or long ago.
          if (f.rx_time_ns > mono || f.rx_time_ns < mono - 1'000'000'000) {
            f.rx_time_ns = mono;
            f.rx_clock = RxClock::ReadTime;
          }
        } else {
          f.rx_time_ns = mono;
          f.rx_clock = RxClock::ReadTime;
          bump(p.counters.rx_unstamped);
        }
        if (f.error) {
          bump(p.counters.rx_error_frames);
          if (auto e = decode_error_frame(f)) {
            p.counters.count_error_event(*e);
            if (auto s = e->state_change()) p.set_state(*s);
          }
        } else {
          bump(p.counters.rx_frames);
          if (p.get_state() == CanState::Unknown || p.get_state() == CanState::Down)
            p.set_state(CanState::ErrorActive);  // frames flow: the controller is on the bus
        }
        out[count++] = f;
      }
      return {count, {}};
    }
    const int e = n < 0 ? errno : EAGAIN;
    if (e == EINTR) continue;
    if (e != EAGAIN && e != EWOULDBLOCK) {
      bump(p.counters.rx_errors);
      if (e == ENETDOWN || e == ENODEV || e == ENXIO) {
        p.set_state(CanState::Down);
        return {0, make_error_code(CanError::kInterfaceDown)};
      }
      return {0, errno_code(e)};
    }
    const int64_t now = rt::now_ns();
    if (now >= deadline_ns) return {};
    const int64_t wait = deadline_ns - now;
    const timespec ts{static_cast<time_t>(wait / 1'000'000'000),
                      static_cast<long>(wait % 1'000'000'000)};
    pollfd pfd{fd_.get(), POLLIN, 0};
    const int r = ppoll(&pfd, 1, &ts, nullptr);
    if (r < 0 && errno != EINTR) {
      bump(p.counters.rx_errors);
      return {0, errno_code(errno)};
    }
    if (r > 0 && (pfd.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0 &&
        (pfd.revents & POLLIN) == 0) {
      // The pending socket error (ENETDOWN) comes out of the next recvmmsg.
      continue;
    }
  }
}

CanState SocketCanPort::state() const noexcept {
  return impl_->get_state();
}

CanPortCounters SocketCanPort::counters() const noexcept {
  return impl_->counters.snapshot();
}

std::error_code SocketCanPort::set_filters(std::span<const CanIdFilter> ids) noexcept {
  if (auto ec = check_filters(ids, kMaxFilters)) return ec;
  std::array<can_filter, kMaxFilters> table{};
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const CanIdFilter& f = ids[i];
    // Full mask over id, format and RTR: exactly this data frame, no remote frames, and a
    // standard id never matches the extended id with the same low bits.
    table[i].can_id = f.extended ? f.id | CAN_EFF_FLAG : f.id;
    table[i].can_mask = (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK) | CAN_EFF_FLAG | CAN_RTR_FLAG;
  }
  // An empty table (length 0) makes the socket receive no data frames at all.
  if (setsockopt(fd_.get(), SOL_CAN_RAW, CAN_RAW_FILTER, ids.empty() ? nullptr : table.data(),
                 static_cast<socklen_t>(ids.size() * sizeof(can_filter))) != 0)
    return errno_code(errno);
  return {};
}

std::error_code SocketCanPort::set_error_mask(uint32_t classes) noexcept {
  const can_err_mask_t mask = classes & err_class::kAll;
  if (setsockopt(fd_.get(), SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof mask) != 0)
    return errno_code(errno);
  return {};
}

Result<CanInterfaceInfo> SocketCanPort::query_interface() noexcept {
  auto link = query_can_link(options_.interface);
  if (!link) return link.error();
  impl_->set_state(link->info.state);
  return link->info;
}

Result<SocketCanSettings> SocketCanPort::read_settings() const noexcept {
  SocketCanSettings s;
  can_err_mask_t mask = 0;
  socklen_t len = sizeof mask;
  if (getsockopt(fd_.get(), SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, &len) != 0)
    return errno_code(errno);
  s.error_mask = mask;
  std::array<can_filter, kMaxFilters> table{};
  len = sizeof table;
  if (getsockopt(fd_.get(), SOL_CAN_RAW, CAN_RAW_FILTER, table.data(), &len) != 0)
    return errno_code(errno);
  s.filter_count = len / sizeof(can_filter);
  int flags = 0;
  len = sizeof flags;
  if (getsockopt(fd_.get(), SOL_SOCKET, SO_TIMESTAMPING, &flags, &len) == 0)
    s.timestamping = (flags & SOF_TIMESTAMPING_RX_SOFTWARE) != 0;
  int ovfl = 0;
  len = sizeof ovfl;
  if (getsockopt(fd_.get(), SOL_SOCKET, SO_RXQ_OVFL, &ovfl, &len) == 0) s.rxq_overflow = ovfl != 0;
  return s;
}

}  // namespace ds1928::canio
