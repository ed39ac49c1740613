#include "canio/virtual_bus.hpp"

#include <fcntl.h>
#include <linux/futex.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <climits>
#include <cstring>
#include <new>

#include "core/spsc_queue.hpp"

namespace ds1928::canio {

// ---- shared layout --------------------------------------------------------------------------

namespace {

constexpr uint64_t kMagic = 0x4453'3139'5643'414EULL;  // "DS19VCAN"
constexpr uint32_t kLayoutVersion = 1;

// One frame on the bus. Every field is an atomic word so that a reader racing a writer (seqlock)
// reads torn values only in a way the sequence check detects, without a data race.
struct Slot {
  // 0: never written; 2t+1: ticket t being written; 2t+2: ticket t complete.
  std::atomic<uint64_t> seq;
  // id (bits 0..28) | extended (29) | rtr (30) | dlc (32..35) | sender (48..63)
  std::atomic<uint64_t> header;
  std::atomic<uint64_t> data;
  std::atomic<int64_t> wire_ns;  // bus clock when sent
};
static_assert(std::atomic<uint64_t>::is_always_lock_free,
              "the ring lives in shared memory: its atomics must be address-free");

uint64_t pack_header(const CanFrame& f, uint16_t sender) noexcept {
  return uint64_t{f.id & kMaxExtendedId} | (uint64_t{f.extended} << 29) | (uint64_t{f.rtr} << 30) |
         (uint64_t{f.dlc} << 32) | (uint64_t{sender} << 48);
}

uint64_t pack_data(const CanFrame& f) noexcept {
  uint64_t d = 0;
  std::memcpy(&d, f.data.data(), 8);
  return d;
}

int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

long futex(std::atomic<uint32_t>* word, int op, uint32_t val, const timespec* timeout) noexcept {
  // Shared (not FUTEX_PRIVATE): the word may live in memory mapped by several processes.
  return syscall(SYS_futex, reinterpret_cast<uint32_t*>(word), op, val, timeout, nullptr, 0);
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

struct VirtualCanBus::Ring {
  uint64_t magic;
  uint32_t version;
  uint32_t capacity;                            // slots, power of two
  std::atomic<uint32_t> ready;                  // 1 once the creator initialised the header
  std::atomic<uint32_t> next_port;              // sender ids
  alignas(64) std::atomic<uint64_t> head;       // next ticket
  alignas(64) std::atomic<uint32_t> published;  // futex word: bumped after every frame
  std::atomic<uint32_t> sleepers;               // readers inside futex wait

  Slot* slots() noexcept { return reinterpret_cast<Slot*>(this + 1); }
  static std::size_t bytes(uint32_t capacity) noexcept {
    return sizeof(Ring) + std::size_t{capacity} * sizeof(Slot);
  }
};
static_assert(alignof(VirtualCanBus::Ring) >= alignof(Slot));

namespace {

using Ring = VirtualCanBus::Ring;

void publish(Ring& ring, const CanFrame& f, uint16_t sender, int64_t wire_ns) noexcept {
  const uint64_t t = ring.head.fetch_add(1, std::memory_order_acq_rel);
  const uint64_t mask = ring.capacity - 1;
  Slot& s = ring.slots()[t & mask];
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

// xorshift64*: small, fast, good enough for loss decisions, reproducible from a seed.
struct Rng {
  uint64_t state = 0x9E37'79B9'7F4A'7C15ULL;
  void seed(uint64_t s) noexcept { state = s != 0 ? s : 0x9E37'79B9'7F4A'7C15ULL; }
  uint32_t next() noexcept {
    state ^= state >> 12;
    state ^= state << 25;
    state ^= state >> 27;
    return static_cast<uint32_t>((state * 0x2545'F491'4F6C'DD1DULL) >> 32);
  }
};

// Loss settings for one direction: written by any thread, applied by the port's own thread.
struct LossControl {
  std::atomic<uint64_t> threshold{0};  // drop when rng < threshold (2^32 = always)
  std::atomic<uint64_t> seed{0};
  std::atomic<uint32_t> seed_generation{0};
  std::atomic<uint32_t> drop_id{0};
  std::atomic<uint32_t> drop_count{0};
  // Owned by the port's thread.
  Rng rng;
  uint32_t applied_generation = 0;

  bool should_drop(uint32_t id) noexcept {
    uint32_t n = drop_count.load(std::memory_order_acquire);
    while (n != 0 && drop_id.load(std::memory_order_relaxed) == id) {
      if (drop_count.compare_exchange_weak(n, n - 1, std::memory_order_acq_rel)) return true;
    }
    const uint64_t th = threshold.load(std::memory_order_relaxed);
    if (th == 0) return false;
    const uint32_t gen = seed_generation.load(std::memory_order_acquire);
    if (gen != applied_generation) {
      applied_generation = gen;
      rng.seed(seed.load(std::memory_order_relaxed));
    }
    return rng.next() < th;
  }
};

struct AtomicCounters {
  std::atomic<uint64_t> tx_frames{0}, tx_queue_full{0}, tx_interface_down{0}, tx_bus_off{0},
      tx_invalid{0}, tx_errors{0}, rx_frames{0}, rx_error_frames{0}, rx_kernel_drops{0},
      rx_errors{0}, bus_off_events{0}, restarts{0}, protocol_errors{0}, controller_errors{0},
      tx_timeouts{0}, no_ack{0};
  std::atomic<uint64_t> rx_lost{0}, tx_lost{0}, delayed{0}, delay_overflow{0}, errors_injected{0},
      sends_failed{0}, missed_off_bus{0};
};

void bump(std::atomic<uint64_t>& c) noexcept {
  c.fetch_add(1, std::memory_order_relaxed);
}

struct Delayed {
  CanFrame frame;
  uint64_t release_poll = 0;
  int64_t release_ns = 0;
  bool by_time = false;  // stamped with release_ns (time delay) rather than the delivery time
};

}  // namespace

// ---- port ---------------------------------------------------------------------------------

struct VirtualCanPort::Impl {
  Ring* ring = nullptr;
  uint16_t sender = 0;
  uint64_t read_pos = 0;

  // Filters: set on the normal thread while the cycle does not run (CanPort contract).
  std::array<CanIdFilter, kMaxFilters> filters{};
  std::size_t filter_count = 0;
  bool filter_all = true;
  std::atomic<uint32_t> error_mask{0};

  std::atomic<uint8_t> state{static_cast<uint8_t>(CanState::ErrorActive)};
  std::atomic<bool> up{true};
  std::atomic<int64_t> bus_off_at{0};
  std::atomic<bool> restart_requested{false};

  LossControl rx_loss, tx_loss;
  std::atomic<uint32_t> delay_polls{0};
  std::atomic<int64_t> delay_ns{0};
  std::atomic<uint32_t> fail_sends{0};
  std::atomic<uint8_t> fail_status{static_cast<uint8_t>(SendStatus::QueueFull)};

  SpscQueue<CanErrorEvent, 16> injected;  // any (one) thread → port thread
  // Error frames the port itself raised (restart), waiting for receive(). Port thread only.
  std::array<CanErrorEvent, 8> own_events{};
  std::size_t own_count = 0;

  static constexpr std::size_t kDelayCapacity = 256;
  std::array<Delayed, kDelayCapacity> delay_queue{};
  std::size_t delay_head = 0, delay_size = 0;
  uint64_t polls = 0;

  AtomicCounters counters;

  bool passes_filter(const CanFrame& f) const noexcept {
    if (filter_all) return true;
    for (std::size_t i = 0; i < filter_count; ++i)
      if (filters[i].id == f.id && filters[i].extended == f.extended) return true;
    return false;
  }

  CanState current_state() const noexcept {
    return static_cast<CanState>(state.load(std::memory_order_acquire));
  }
  void set_state(CanState s) noexcept {
    state.store(static_cast<uint8_t>(s), std::memory_order_release);
  }

  // A bus-off controller comes back after restart-ms on the bus clock (as the kernel's
  // can_restart does), or at once after restart(); either way with a "restarted" error frame.
  void maybe_restart(int64_t now, uint32_t restart_ms) noexcept {
    if (current_state() != CanState::BusOff) return;
    const bool manual = restart_requested.exchange(false, std::memory_order_acq_rel);
    const bool timed = restart_ms != 0 && now - bus_off_at.load(std::memory_order_acquire) >=
                                              int64_t{restart_ms} * 1'000'000;
    if (!manual && !timed) return;
    set_state(CanState::ErrorActive);
    if (own_count < own_events.size()) {
      CanErrorEvent e;
      e.restarted = true;
      e.classes = err_class::kRestarted;
      own_events[own_count++] = e;
    }
  }

  void count_event(const CanErrorEvent& e) noexcept {
    if (e.bus_off) bump(counters.bus_off_events);
    if (e.restarted) bump(counters.restarts);
    if (e.protocol) bump(counters.protocol_errors);
    if (e.controller) bump(counters.controller_errors);
    if (e.tx_timeout) bump(counters.tx_timeouts);
    if (e.no_ack) bump(counters.no_ack);
  }
};

VirtualCanPort::VirtualCanPort(std::shared_ptr<VirtualCanBus> bus, uint16_t index,
                               VirtualPortOptions options)
    : bus_(std::move(bus)), options_(std::move(options)), impl_(std::make_unique<Impl>()) {
  impl_->ring = bus_->ring_;
  impl_->sender = index;
  impl_->read_pos = impl_->ring->head.load(std::memory_order_acquire);
}

VirtualCanPort::~VirtualCanPort() = default;

SendResult VirtualCanPort::send(const CanFrame& frame) noexcept {
  Impl& p = *impl_;
  const int64_t now = bus_->now_ns();
  p.maybe_restart(now, options_.restart_ms);
  if (!is_sendable(frame)) {
    bump(p.counters.tx_invalid);
    return {SendStatus::InvalidFrame, EINVAL};
  }
  if (!p.up.load(std::memory_order_acquire)) {
    bump(p.counters.tx_interface_down);
    return {SendStatus::InterfaceDown, ENETDOWN};
  }
  if (p.current_state() == CanState::BusOff) {
    bump(p.counters.tx_bus_off);
    return {SendStatus::BusOff, 0};
  }
  uint32_t n = p.fail_sends.load(std::memory_order_acquire);
  while (n != 0) {
    if (p.fail_sends.compare_exchange_weak(n, n - 1, std::memory_order_acq_rel)) {
      bump(p.counters.sends_failed);
      const auto st = static_cast<SendStatus>(p.fail_status.load(std::memory_order_relaxed));
      switch (st) {
        case SendStatus::QueueFull:
          bump(p.counters.tx_queue_full);
          return {st, ENOBUFS};
        case SendStatus::InterfaceDown:
          bump(p.counters.tx_interface_down);
          return {st, ENETDOWN};
        default:
          bump(p.counters.tx_errors);
          return {SendStatus::Failed, EIO};
      }
    }
  }
  bump(p.counters.tx_frames);
  if (p.tx_loss.should_drop(frame.id)) {
    bump(p.counters.tx_lost);  // the sender cannot know: a real controller would retry or not
    return {};
  }
  publish(*p.ring, frame, p.sender, now);
  return {};
}

ReceiveResult VirtualCanPort::receive(std::span<CanFrame> out, int64_t deadline_ns) noexcept {
  Impl& p = *impl_;
  Ring& ring = *p.ring;
  ++p.polls;
  const uint64_t mask = ring.capacity - 1;
  for (;;) {
    const uint32_t seen = ring.published.load(std::memory_order_seq_cst);
    const int64_t now = bus_->now_ns();
    std::size_t count = 0;
    const uint32_t error_mask = p.error_mask.load(std::memory_order_relaxed);

    auto deliver_event = [&](const CanErrorEvent& e) noexcept {
      p.count_event(e);
      CanFrame f = encode_error_frame(e);
      if ((f.id & error_mask) == 0 || count == out.size()) return;
      f.rx_time_ns = now;
      f.rx_clock = RxClock::VirtualBus;
      out[count++] = f;
      bump(p.counters.rx_error_frames);
    };

    // Injected error frames: the state change happens whether or not the class is subscribed,
    // as in the kernel.
    while (count < out.size()) {
      auto e = p.injected.try_pop();
      if (!e) break;
      if (auto s = e->state_change()) {
        if (*s == CanState::BusOff && p.current_state() != CanState::BusOff)
          p.bus_off_at.store(now, std::memory_order_release);
        p.set_state(*s);
      }
      deliver_event(*e);
    }
    p.maybe_restart(now, options_.restart_ms);
    {
      std::size_t i = 0;
      for (; i < p.own_count && count < out.size(); ++i) deliver_event(p.own_events[i]);
      for (std::size_t j = i; j < p.own_count; ++j) p.own_events[j - i] = p.own_events[j];
      p.own_count -= i;
    }

    const bool on_bus =
        p.up.load(std::memory_order_acquire) && p.current_state() != CanState::BusOff;
    const bool delaying = p.delay_polls.load(std::memory_order_relaxed) != 0 ||
                          p.delay_ns.load(std::memory_order_relaxed) != 0 || p.delay_size != 0;

    // Frames from the ring.
    const uint64_t head = ring.head.load(std::memory_order_acquire);
    while (p.read_pos < head && (delaying || count < out.size())) {
      Slot& s = ring.slots()[p.read_pos & mask];
      const uint64_t want = 2 * p.read_pos + 2;
      const uint64_t s1 = s.seq.load(std::memory_order_acquire);
      if (s1 < want) break;  // ticket taken, frame not yet written: next poll
      uint64_t header = 0, data = 0;
      int64_t wire = 0;
      bool torn = s1 != want;
      if (!torn) {
        header = s.header.load(std::memory_order_relaxed);
        data = s.data.load(std::memory_order_relaxed);
        wire = s.wire_ns.load(std::memory_order_relaxed);
        std::atomic_thread_fence(std::memory_order_acquire);
        torn = s.seq.load(std::memory_order_relaxed) != s1;
      }
      if (torn) {
        // Lapped by the writers: the frames between here and the oldest slot still intact are
        // gone, as with a full socket receive queue.
        const uint64_t h = ring.head.load(std::memory_order_acquire);
        const uint64_t oldest = h > ring.capacity ? h - ring.capacity + 1 : 0;
        const uint64_t next = oldest > p.read_pos + 1 ? oldest : p.read_pos + 1;
        p.counters.rx_kernel_drops.fetch_add(next - p.read_pos, std::memory_order_relaxed);
        p.read_pos = next;
        continue;
      }
      ++p.read_pos;
      const auto sender = static_cast<uint16_t>(header >> 48);
      if (sender == p.sender) continue;  // like CAN_RAW without RECV_OWN_MSGS
      if (!on_bus) {
        bump(p.counters.missed_off_bus);
        continue;
      }
      CanFrame f;
      f.id = static_cast<uint32_t>(header & kMaxExtendedId);
      f.extended = ((header >> 29) & 1) != 0;
      f.rtr = ((header >> 30) & 1) != 0;
      f.dlc = static_cast<uint8_t>((header >> 32) & 0xF);
      std::memcpy(f.data.data(), &data, 8);
      f.rx_time_ns = wire;
      f.rx_clock = RxClock::VirtualBus;
      if (!p.passes_filter(f)) continue;
      if (p.rx_loss.should_drop(f.id)) {
        bump(p.counters.rx_lost);
        continue;
      }
      if (delaying) {
        if (p.delay_size == Impl::kDelayCapacity) {
          bump(p.counters.delay_overflow);
          continue;
        }
        Delayed& d = p.delay_queue[(p.delay_head + p.delay_size) % Impl::kDelayCapacity];
        d.frame = f;
        d.release_poll = p.polls + p.delay_polls.load(std::memory_order_relaxed);
        const int64_t delay = p.delay_ns.load(std::memory_order_relaxed);
        d.release_ns = wire + delay;
        d.by_time = delay != 0;
        ++p.delay_size;
        bump(p.counters.delayed);
        continue;
      }
      out[count++] = f;
      bump(p.counters.rx_frames);
    }
    // Delayed frames whose time (polls and bus clock) has come, oldest first.
    int64_t next_release = 0;
    while (p.delay_size != 0 && count < out.size()) {
      Delayed& d = p.delay_queue[p.delay_head];
      if (d.release_poll > p.polls || d.release_ns > now) {
        if (d.release_poll <= p.polls) next_release = d.release_ns;
        break;
      }
      CanFrame f = d.frame;
      // Stamped when it finally arrives, as a late frame on a real bus would be.
      f.rx_time_ns = d.by_time ? d.release_ns : now;
      out[count++] = f;
      bump(p.counters.rx_frames);
      p.delay_head = (p.delay_head + 1) % Impl::kDelayCapacity;
      --p.delay_size;
    }

    if (!p.up.load(std::memory_order_acquire) && count == 0) {
      bump(p.counters.rx_errors);
      return {0, make_error_code(CanError::kInterfaceDown)};
    }
    if (count != 0 || now >= deadline_ns) return {count, {}};

    // Sleep until a frame is published, a delayed frame is due, or the deadline.
    int64_t until = deadline_ns;
    if (next_release != 0 && next_release < until) until = next_release;
    const int64_t wait = until - now;
    if (wait <= 0) continue;
    timespec ts{static_cast<time_t>(wait / 1'000'000'000), static_cast<long>(wait % 1'000'000'000)};
    ring.sleepers.fetch_add(1, std::memory_order_seq_cst);
    if (ring.published.load(std::memory_order_seq_cst) == seen)
      futex(&ring.published, FUTEX_WAIT, seen, &ts);
    ring.sleepers.fetch_sub(1, std::memory_order_seq_cst);
    // A fake clock does not move while we sleep: give up after one real wait of the remaining
    // time rather than spinning on a deadline that never comes.
    if (bus_->options_.clock && bus_->now_ns() == now &&
        ring.published.load(std::memory_order_seq_cst) == seen)
      return {0, {}};
  }
}

CanState VirtualCanPort::state() const noexcept {
  if (!impl_->up.load(std::memory_order_acquire)) return CanState::Down;
  return impl_->current_state();
}

CanPortCounters VirtualCanPort::counters() const noexcept {
  const AtomicCounters& c = impl_->counters;
  auto r = [](const std::atomic<uint64_t>& a) { return a.load(std::memory_order_relaxed); };
  CanPortCounters s;
  s.tx_frames = r(c.tx_frames);
  s.tx_queue_full = r(c.tx_queue_full);
  s.tx_interface_down = r(c.tx_interface_down);
  s.tx_bus_off = r(c.tx_bus_off);
  s.tx_invalid = r(c.tx_invalid);
  s.tx_errors = r(c.tx_errors);
  s.rx_frames = r(c.rx_frames);
  s.rx_error_frames = r(c.rx_error_frames);
  s.rx_kernel_drops = r(c.rx_kernel_drops);
  s.rx_errors = r(c.rx_errors);
  s.bus_off_events = r(c.bus_off_events);
  s.restarts = r(c.restarts);
  s.protocol_errors = r(c.protocol_errors);
  s.controller_errors = r(c.controller_errors);
  s.tx_timeouts = r(c.tx_timeouts);
  s.no_ack = r(c.no_ack);
  return s;
}

FaultCounters VirtualCanPort::fault_counters() const noexcept {
  const AtomicCounters& c = impl_->counters;
  auto r = [](const std::atomic<uint64_t>& a) { return a.load(std::memory_order_relaxed); };
  FaultCounters f;
  f.rx_lost = r(c.rx_lost);
  f.tx_lost = r(c.tx_lost);
  f.delayed = r(c.delayed);
  f.delay_overflow = r(c.delay_overflow);
  f.errors_injected = r(c.errors_injected);
  f.sends_failed = r(c.sends_failed);
  f.missed_off_bus = r(c.missed_off_bus);
  return f;
}

std::error_code VirtualCanPort::set_filters(std::span<const CanIdFilter> ids) noexcept {
  if (ids.size() > kMaxFilters) return CanError::kTooManyFilters;
  for (const auto& f : ids)
    if (f.id > (f.extended ? kMaxExtendedId : kMaxStandardId)) return CanError::kInvalidFrame;
  std::copy(ids.begin(), ids.end(), impl_->filters.begin());
  impl_->filter_count = ids.size();
  impl_->filter_all = false;
  return {};
}

std::error_code VirtualCanPort::set_error_mask(uint32_t classes) noexcept {
  impl_->error_mask.store(classes & err_class::kAll, std::memory_order_relaxed);
  return {};
}

Result<CanInterfaceInfo> VirtualCanPort::query_interface() noexcept {
  CanInterfaceInfo info;
  info.ifindex = impl_->sender;
  info.up = impl_->up.load(std::memory_order_acquire);
  info.running = info.up;
  info.state = state();
  info.bitrate = options_.bitrate;
  info.sample_point = 875;
  info.restart_ms = options_.restart_ms;
  return info;
}

void VirtualCanPort::set_loss(FaultDirection dir, double probability, uint64_t seed) noexcept {
  LossControl& l = dir == FaultDirection::Rx ? impl_->rx_loss : impl_->tx_loss;
  const double p = probability < 0 ? 0 : (probability > 1 ? 1 : probability);
  l.seed.store(seed, std::memory_order_relaxed);
  l.seed_generation.fetch_add(1, std::memory_order_release);
  l.threshold.store(static_cast<uint64_t>(p * 4294967296.0), std::memory_order_relaxed);
}

void VirtualCanPort::drop_next(FaultDirection dir, uint32_t id, uint32_t count) noexcept {
  LossControl& l = dir == FaultDirection::Rx ? impl_->rx_loss : impl_->tx_loss;
  l.drop_count.store(0, std::memory_order_release);
  l.drop_id.store(id, std::memory_order_relaxed);
  l.drop_count.store(count, std::memory_order_release);
}

void VirtualCanPort::set_delay_polls(uint32_t polls) noexcept {
  impl_->delay_polls.store(polls, std::memory_order_relaxed);
}

void VirtualCanPort::set_delay_ns(int64_t ns) noexcept {
  impl_->delay_ns.store(ns < 0 ? 0 : ns, std::memory_order_relaxed);
}

bool VirtualCanPort::inject_error(const CanErrorEvent& event) noexcept {
  if (!impl_->injected.try_push(event)) return false;
  bump(impl_->counters.errors_injected);
  return true;
}

bool VirtualCanPort::inject_bus_off() noexcept {
  CanErrorEvent e;
  e.bus_off = true;
  e.classes = err_class::kBusOff;
  // Refuse sends at once (the injecting thread expects it); the event itself, with its error
  // frame, reaches the port's thread through the queue.
  impl_->bus_off_at.store(bus_->now_ns(), std::memory_order_release);
  impl_->set_state(CanState::BusOff);
  return inject_error(e);
}

void VirtualCanPort::restart() noexcept {
  impl_->restart_requested.store(true, std::memory_order_release);
}

void VirtualCanPort::set_up(bool up) noexcept {
  impl_->up.store(up, std::memory_order_release);
}

void VirtualCanPort::fail_next_sends(uint32_t count, SendStatus status) noexcept {
  impl_->fail_status.store(static_cast<uint8_t>(status), std::memory_order_relaxed);
  impl_->fail_sends.store(count, std::memory_order_release);
}

// ---- bus ----------------------------------------------------------------------------------

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
