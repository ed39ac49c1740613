#include <time.h>

#include <array>
#include <cerrno>
#include <climits>
#include <cstring>

#include "can/bit_budget.hpp"
#include "can/can_port_counters.hpp"
#include "can/virtual_bus.hpp"
#include "can/virtual_bus_ring.hpp"
#include "core/spsc_queue.hpp"

namespace ds1928::canio {
namespace {

using Ring = VirtualCanBus::Ring;
using vbus::futex;
using vbus::publish;
using vbus::Slot;

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

// The port's counters and the virtual bus's fault counters.
struct AtomicCounters : AtomicCanPortCounters {
  std::atomic<uint64_t> rx_lost{0}, tx_lost{0}, delayed{0}, delay_overflow{0}, errors_injected{0},
      sends_failed{0}, missed_off_bus{0};
};

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
  // Bus-off error frames announced by inject_bus_off() (state already applied there), waiting
  // for receive().
  std::atomic<uint32_t> bus_off_frames{0};

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

  // The state change an error event announces, as the kernel makes it whether or not the port
  // subscribed to the event's class.
  void apply_event(const CanErrorEvent& e, int64_t now) noexcept {
    const auto s = e.state_change();
    if (!s) return;
    if (*s == CanState::BusOff && current_state() != CanState::BusOff)
      bus_off_at.store(now, std::memory_order_release);
    set_state(*s);
  }

  void count_event(const CanErrorEvent& e) noexcept { counters.count_error_event(e); }
};

VirtualCanPort::VirtualCanPort(std::shared_ptr<VirtualCanBus> bus, uint16_t index,
                               VirtualPortOptions options)
    : bus_(std::move(bus)), options_(std::move(options)), impl_(std::make_unique<Impl>()) {
  impl_->ring = bus_->ring_;
  impl_->sender = index;
  impl_->read_pos = impl_->ring->head.load(std::memory_order_acquire);
}

VirtualCanPort::~VirtualCanPort() {
  // Frames still queued go out (as a controller finishes its TX buffer); the queue is taken by
  // another port only once drained.
  if (tx_queue_ >= 0) impl_->ring->tx[tx_queue_].owner.store(0, std::memory_order_release);
}

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
  if (tx_queue_ < 0) {
    bump(p.counters.tx_frames);
    if (p.tx_loss.should_drop(frame.id)) {
      bump(p.counters.tx_lost);  // the sender cannot know: a real controller would retry or not
      return {};
    }
    publish(*p.ring, frame, p.sender, now);
    return {};
  }
  // Timed bus: into this port's TX queue; the frame goes on the wire when the bus is free and
  // it wins arbitration. Never waits: a full queue is ENOBUFS, as from a SocketCAN socket.
  Ring& ring = *p.ring;
  vbus::TxQueue& q = ring.tx[tx_queue_];
  (void)vbus::advance(ring, now);  // frames whose turn came free their TX slots first
  const uint64_t head = q.head.load(std::memory_order_relaxed);
  if (head - q.tail.load(std::memory_order_acquire) >= vbus::kTxDepth) {
    bump(p.counters.tx_queue_full);
    return {SendStatus::QueueFull, ENOBUFS};
  }
  bump(p.counters.tx_frames);
  if (p.tx_loss.should_drop(frame.id)) {
    bump(p.counters.tx_lost);  // lost before the wire: takes no bus time
    return {};
  }
  vbus::TxEntry& e = q.entries[head % vbus::kTxDepth];
  e.header.store(vbus::pack_header(frame, p.sender), std::memory_order_relaxed);
  e.data.store(vbus::pack_data(frame), std::memory_order_relaxed);
  e.ready_ns.store(now, std::memory_order_relaxed);
  q.head.store(head + 1, std::memory_order_release);
  (void)vbus::advance(ring, now);  // an idle bus starts it at once
  return {};
}

ReceiveResult VirtualCanPort::receive(std::span<CanFrame> out, int64_t deadline_ns) noexcept {
  Impl& p = *impl_;
  Ring& ring = *p.ring;
  if (out.empty()) return {};
  ++p.polls;
  const uint64_t mask = ring.capacity - 1;
  for (;;) {
    const uint32_t seen = ring.published.load(std::memory_order_seq_cst);
    const int64_t now = bus_->now_ns();
    // Timed bus: frames whose turn has come go on the wire (any port may advance the timeline).
    const int64_t next_start = vbus::advance(ring, now);
    int64_t next_due = INT64_MAX;  // end of frame of the first frame still on the wire
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

    // Bus-off announced by inject_bus_off(): the frame only, its state change is made.
    for (uint32_t n = p.bus_off_frames.load(std::memory_order_acquire);
         n != 0 && count < out.size();) {
      if (!p.bus_off_frames.compare_exchange_weak(n, n - 1, std::memory_order_acq_rel)) continue;
      CanErrorEvent e;
      e.bus_off = true;
      e.classes = err_class::kBusOff;
      deliver_event(e);
      n = p.bus_off_frames.load(std::memory_order_acquire);
    }
    // Injected error frames: the state change happens whether or not the class is subscribed,
    // as in the kernel.
    while (count < out.size()) {
      auto e = p.injected.try_pop();
      if (!e) break;
      p.apply_event(*e, now);
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
    const bool timed = ring.bitrate != 0;
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
      if (!torn && timed && wire > now) {
        // Timed bus: still on the wire; receivers get it at its end of frame. Frames are on
        // the ring in bus order, so nothing behind it is due either.
        next_due = wire;
        break;
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
      if (((header >> 31) & 1) != 0) {
        // broadcast_error() from another port: as if this port's controller had reported it.
        CanFrame ef;
        ef.error = true;
        ef.id = static_cast<uint32_t>(header & err_class::kAll);
        ef.dlc = 8;
        std::memcpy(ef.data.data(), &data, 8);
        if (auto e = decode_error_frame(ef)) {
          if (count == out.size()) {
            --p.read_pos;  // no room: take it with the next call
            break;
          }
          p.apply_event(*e, now);
          deliver_event(*e);
        }
        continue;
      }
      if (!on_bus) {
        bump(p.counters.missed_off_bus);
        continue;
      }
      CanFrame f = vbus::unpack(header, data);
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

    // Sleep until a frame is published, a delayed frame is due, a frame on the wire ends, the
    // next queued frame can start, or the deadline.
    int64_t until = deadline_ns;
    if (next_release != 0 && next_release < until) until = next_release;
    if (next_due < until) until = next_due;
    if (next_start < until) until = next_start;
    const int64_t wait = until - now;
    if (wait <= 0) continue;
    if (bus_->options_.wait_until) {
      bus_->options_.wait_until(until);
      if (bus_->now_ns() == now && ring.published.load(std::memory_order_seq_cst) == seen)
        return {0, {}};
      continue;
    }
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
  return impl_->counters.snapshot();
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
  if (auto ec = check_filters(ids, kMaxFilters)) return ec;
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
  info.bitrate = bus_->timed() ? bus_->bitrate() : options_.bitrate;
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
  // The state changes at once (the injecting thread expects sends to be refused from now on);
  // the bus-off error frame reaches the port's thread with its next receive().
  impl_->bus_off_at.store(bus_->now_ns(), std::memory_order_release);
  impl_->set_state(CanState::BusOff);
  impl_->bus_off_frames.fetch_add(1, std::memory_order_acq_rel);
  bump(impl_->counters.errors_injected);
  return true;
}

bool VirtualCanPort::broadcast_error(const CanErrorEvent& event) noexcept {
  publish(*impl_->ring, encode_error_frame(event), impl_->sender, bus_->now_ns());
  bump(impl_->counters.errors_injected);
  return true;
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

}  // namespace ds1928::canio
