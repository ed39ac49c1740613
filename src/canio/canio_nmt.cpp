// The CAN-I/O driver's node lifecycle (CiA 301): NMT Start after a node's configuration and its
// repetition with back-off while the node stays silent, boot-up and heartbeat (0x700 + node),
// EMCY (0x080 + node). All on the cycle thread, from the node port (the SDO socket), never from
// the cycle port: none of these frames wakes the response window. Every event the daemon must
// hear of is counted per node and queued (push_event()); the normal thread takes it with
// poll_event() — the one place a later hook (flight recorder) attaches to.
#include <algorithm>

#include "canio/canio_bus.hpp"
#include "core/single_writer.hpp"

namespace ds1928::canio {
namespace {

constexpr int64_t kMs = 1'000'000;
// NMT Start repeated while a configured node stays silent: 100 ms, doubling, at most 5 s.
constexpr int64_t kStartBackoffFirstNs = 100 * kMs;
constexpr int64_t kStartBackoffMaxNs = 5000 * kMs;

}  // namespace

std::string_view to_string(CanioNodeEventKind k) noexcept {
  switch (k) {
    case CanioNodeEventKind::BootUp:
      return "boot-up";
    case CanioNodeEventKind::HeartbeatMissed:
      return "heartbeat-missed";
    case CanioNodeEventKind::Emcy:
      return "emcy";
    case CanioNodeEventKind::StartRetry:
      return "start-retry";
    case CanioNodeEventKind::BusOff:
      return "bus-off";
    case CanioNodeEventKind::BusRestarted:
      return "bus-restarted";
    case CanioNodeEventKind::IdentityMismatch:
      return "identity-mismatch";
    case CanioNodeEventKind::IdentityConfirmed:
      return "identity-confirmed";
  }
  return "?";
}

std::size_t CanioBus::node_index(uint8_t node) const noexcept {
  for (std::size_t k = 0; k < nodes_.size(); ++k)
    if (nodes_[k].node == node) return k;
  return nodes_.size();
}

void CanioBus::push_event(const CanioNodeEvent& e) noexcept {
  if (!events_.try_push(e)) single_writer_add(counters_.events_dropped);
}

bool CanioBus::poll_event(CanioNodeEvent& out) noexcept {
  auto e = events_.try_pop();
  if (!e) return false;
  out = *e;
  return true;
}

void CanioBus::drain_node_port(int64_t now) noexcept {
  if (!sdo_port_) return;
  for (;;) {
    const ReceiveResult rr = sdo_port_->receive(sdo_rx_, 0);
    for (std::size_t j = 0; j < rr.count; ++j) {
      const CanFrame& f = sdo_rx_[j];
      if (f.error || f.extended) continue;
      if (f.id > kErrorControlBase && f.id <= kErrorControlBase + 127) {
        const auto ec = parse_error_control(f);
        const std::size_t k = ec ? node_index(ec->node) : nodes_.size();
        if (k < nodes_.size()) on_error_control(k, ec->state, now);
        continue;
      }
      if (f.id > kEmcyBase && f.id <= kEmcyBase + 127) {
        const auto e = parse_emcy(f);
        const std::size_t k = e ? node_index(e->node) : nodes_.size();
        if (k < nodes_.size()) on_emcy(k, *e, now);
        continue;
      }
      if (auto o = sdo_client_.receive(f)) transfer_done(now, o->error, o->value, o->size);
    }
    if (rr.error || rr.count < sdo_rx_.size()) break;
  }
}

void CanioBus::node_down(std::size_t k, bool fresh, int64_t now) noexcept {
  NodeTrack& t = nodes_[k];
  for (std::size_t i = 0; i < axis_node_.size(); ++i) {
    if (axis_node_[i] != k) continue;
    AxisSdo& a = axis_sdo_[i];
    axis_counters_[i].configured.store(false, std::memory_order_release);
    a.reconfigure = true;
    a.fresh = a.fresh || fresh;
    a.retry_at_ns = now;
    a.definitive = 0;
    if (fresh) {
      // A node that restarted is a new chance for a register it refused before.
      a.backoff_ns = 0;
      axis_counters_[i].unconfigurable.store(false, std::memory_order_relaxed);
    }
    // A configuration, check or identity read in progress for this node is void: it restarts
    // from the first register.
    if ((job_.kind == SdoJobKind::Configure || job_.kind == SdoJobKind::Check ||
         job_.kind == SdoJobKind::Identity) &&
        job_.axis == i) {
      sdo_client_.cancel();
      job_.kind = SdoJobKind::None;
    }
  }
  t.start_due = false;
  t.started = false;
  t.heartbeat_deadline_ns = 0;
  t.trust_by_heartbeat = false;
  // Who answers now is read again before its modules are configured or checked: a boot-up may
  // be another node (replaced), a silence may end with another node on the cable.
  t.identity_due = t.identity_mask != 0;
  if (fresh && t.identity_mask != 0) {
    t.identity_backoff_ns = 0;
    if (t.identity_state == NodeIdentityState::Confirmed) {
      t.identity_state = NodeIdentityState::Pending;
      publish_identity(k);
    }
  }
}

void CanioBus::on_error_control(std::size_t k, NmtState state, int64_t now) noexcept {
  NodeTrack& t = nodes_[k];
  CanioNodeCounters& nc = node_counters_[k];
  nc.nmt_state.store(static_cast<uint8_t>(state), std::memory_order_relaxed);
  if (state == NmtState::BootUp) {
    // The node (re)started: pre-operational, its modules back at their power-up settings
    // (EnDat disabled). Its axes are down from now on and configured anew.
    single_writer_add(nc.boot_ups);
    push_event({CanioNodeEventKind::BootUp, t.node, now, {}, 0});
    if (!options_.assume_configured) node_down(k, true, now);
    return;
  }
  single_writer_add(nc.heartbeats);
  if (t.heartbeat_deadline_ns != 0) t.heartbeat_deadline_ns = now + t.consumer_ns;
  if (options_.assume_configured) return;
  if (state == NmtState::Operational && t.trust_by_heartbeat) {
    // After a bus restart: an OPERATIONAL heartbeat proves the node did not reset (a reset
    // sends boot-up and waits pre-operational): the same node, its identity as last read.
    t.trust_by_heartbeat = false;
    if (!identity_refused(k)) t.identity_due = false;
    for (std::size_t i = 0; i < axis_node_.size(); ++i) {
      if (axis_node_[i] != k || !axis_sdo_[i].reconfigure || axis_sdo_[i].fresh) continue;
      if (axis_counters_[i].configurations.load(std::memory_order_relaxed) == 0) continue;
      if (job_.kind == SdoJobKind::Check && job_.axis == i) {
        sdo_client_.cancel();
        job_.kind = SdoJobKind::None;
      }
      mark_configured(i, now);
    }
    return;
  }
  // A heartbeat produced before the node took the Start still says pre-operational: only one
  // that comes two producer times (at least input_timeout_ms) after the Start counts.
  const int64_t grace_ns = std::max<int64_t>(2 * int64_t{t.heartbeat_ms} * kMs,
                                             int64_t{options_.bus.input_timeout_ms} * kMs);
  if (state != NmtState::Operational && t.started && options_.bus.nmt == CanNmt::Start &&
      !t.start_due && now - t.start_sent_ns > grace_ns) {
    // Configured and started, but it reports another state (stopped or pre-operational by a
    // tool or by itself): Start again, with the back-off of a silent node.
    t.start_due = true;
  }
}

void CanioBus::on_emcy(std::size_t k, const Emcy& e, int64_t now) noexcept {
  CanioNodeCounters& nc = node_counters_[k];
  single_writer_add(nc.emcys);
  uint64_t w = uint64_t{e.error_code} | (uint64_t{e.error_register} << 16);
  for (std::size_t j = 0; j < e.vendor.size(); ++j) w |= uint64_t{e.vendor[j]} << (24 + 8 * j);
  nc.last_emcy.store(w, std::memory_order_relaxed);
  push_event({CanioNodeEventKind::Emcy, nodes_[k].node, now, e, 0});
}

void CanioBus::node_configured(std::size_t axis, int64_t now) noexcept {
  const std::size_t k = axis_node_[axis];
  for (std::size_t i = 0; i < axis_node_.size(); ++i)
    if (axis_node_[i] == k && axis_sdo_[i].reconfigure) return;  // not all of its modules yet
  NodeTrack& t = nodes_[k];
  t.start_due = options_.bus.nmt == CanNmt::Start;
  t.started = false;
  t.start_backoff_ns = 0;
  t.next_start_ns = now;
  t.trust_by_heartbeat = false;
  if (t.heartbeat_ms != 0 && node_counters_[k].heartbeat_watched.load(std::memory_order_relaxed))
    t.heartbeat_deadline_ns = now + t.consumer_ns;
}

void CanioBus::step_nmt(int64_t now) noexcept {
  const int64_t input_timeout_ns = int64_t{options_.bus.input_timeout_ms} * kMs;
  for (std::size_t k = 0; k < nodes_.size(); ++k) {
    NodeTrack& t = nodes_[k];
    CanioNodeCounters& nc = node_counters_[k];
    if (t.heartbeat_deadline_ns != 0 && now > t.heartbeat_deadline_ns) {
      // Heartbeat consumer timeout: the node is gone or hangs. Its axes go down until a check
      // (or a boot-up) proves the configuration again.
      single_writer_add(nc.heartbeat_misses);
      // Its state is no longer known (status, the module state): none until it is heard again.
      nc.nmt_state.store(0xFF, std::memory_order_relaxed);
      push_event({CanioNodeEventKind::HeartbeatMissed,
                  t.node,
                  now,
                  {},
                  static_cast<uint32_t>(t.consumer_ns / kMs)});
      node_down(k, false, now);
      continue;
    }
    if (options_.bus.nmt != CanNmt::Start || !sdo_port_ || options_.assume_configured) continue;
    bool send = false;
    if (t.start_due && now >= t.next_start_ns) {
      send = true;
      t.start_due = false;
      if (t.started) {
        // Asked again (the node reported another state): bounded back-off.
        t.start_backoff_ns = t.start_backoff_ns == 0
                                 ? kStartBackoffFirstNs
                                 : std::min(2 * t.start_backoff_ns, kStartBackoffMaxNs);
        t.next_start_ns = now + t.start_backoff_ns;
        single_writer_add(nc.start_retries);
        push_event({CanioNodeEventKind::StartRetry,
                    t.node,
                    now,
                    {},
                    static_cast<uint32_t>(t.start_backoff_ns / kMs)});
      }
    } else if (t.started && now - t.start_sent_ns > input_timeout_ns && now >= t.next_start_ns) {
      // Configured and started, but none of its axes delivers: Start again, with back-off.
      bool silent = true;
      for (std::size_t i = 0; i < axis_node_.size(); ++i)
        if (axis_node_[i] == k && !axis_counters_[i].silent.load(std::memory_order_relaxed))
          silent = false;
      if (silent) {
        send = true;
        t.start_backoff_ns = t.start_backoff_ns == 0
                                 ? kStartBackoffFirstNs
                                 : std::min(2 * t.start_backoff_ns, kStartBackoffMaxNs);
        t.next_start_ns = now + t.start_backoff_ns;
        single_writer_add(nc.start_retries);
        push_event({CanioNodeEventKind::StartRetry,
                    t.node,
                    now,
                    {},
                    static_cast<uint32_t>(t.start_backoff_ns / kMs)});
      }
    }
    if (!send) continue;
    if (auto f = build_nmt(NmtCommand::Start, t.node); f && sdo_port_->send(*f).sent()) {
      single_writer_add(nc.nmt_starts);
      t.started = true;
      t.start_sent_ns = now;
    } else {
      t.start_due = true;  // not on the wire (queue full, bus-off): next cycle
    }
  }
}

}  // namespace ds1928::canio
