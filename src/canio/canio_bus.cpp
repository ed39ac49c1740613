#include "canio/canio_bus.hpp"

#include <algorithm>

#include "can/can_error_frame.hpp"
#include "can/can_netlink.hpp"
#include "can/errors.hpp"
#include "canio/sdo_expedited.hpp"
#include "core/clock.hpp"
#include "core/single_writer.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::canio {
namespace {

class CanioBusCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "canio-bus"; }
  [[nodiscard]] std::string message(int e) const override {
    switch (static_cast<CanioBusError>(e)) {
      case CanioBusError::kNoAcyclicTransport:
        return "no acyclic transport (canio.acyclic.transport: none): the module cannot be "
               "configured";
      case CanioBusError::kSdoTimeout:
        return "no SDO response (node silent or not a CANopen SDO server)";
      case CanioBusError::kReadBackMismatch:
        return "the register reads back another value than was written";
      case CanioBusError::kNoSdoObject:
        return "the register has no SDO object (canio.acyclic.sdo_objects)";
      case CanioBusError::kNotConfigured:
        return "the module is not configured yet";
      case CanioBusError::kSdoSendFailed:
        return "the SDO request could not be sent";
      case CanioBusError::kNoSuchAxis:
        return "no such axis";
      case CanioBusError::kReadBackSize:
        return "the register reads back with another size than it has";
      case CanioBusError::kNodeReset:
        return "the node announced a reset (boot-up): configured anew";
    }
    return "unknown CAN-I/O bus error";
  }
};

}  // namespace

std::string_view to_string(CanioAxisState s) noexcept {
  switch (s) {
    case CanioAxisState::Configuring:
      return "configuring";
    case CanioAxisState::AwaitingPosCycle:
      return "awaiting_pos_cycle";
    case CanioAxisState::Operational:
      return "operational";
    case CanioAxisState::Silent:
      return "silent";
    case CanioAxisState::Starting:
      return "starting";
    case CanioAxisState::Unconfigurable:
      return "unconfigurable";
    case CanioAxisState::IdentityMismatch:
      return "identity_mismatch";
  }
  return "?";
}

std::string_view reason(CanioAxisState s) noexcept {
  switch (s) {
    case CanioAxisState::Configuring:
      return "its node is being configured over SDO (EnDatMode, MTUs, Rescan): axis BusDown";
    case CanioAxisState::AwaitingPosCycle:
      return "configured, but PosCycle has not changed since: no new position yet (Stale)";
    case CanioAxisState::Operational:
      return "";
    case CanioAxisState::Silent:
      return "no complete sample within input_timeout_ms (Stale)";
    case CanioAxisState::Starting:
      return "configured, NMT Start sent, no process data yet: Start repeated with back-off";
    case CanioAxisState::Unconfigurable:
      return "unconfigurable: a register the axis needs was refused; retried with back-off";
    case CanioAxisState::IdentityMismatch:
      return "its node's identity (0x1000 / 0x1018) is not the expected one: not started";
  }
  return "";
}

const std::error_category& canio_bus_category() noexcept {
  static const CanioBusCategory category;
  return category;
}

std::string check_interface(CanPort& port, uint32_t expected_bitrate) {
  auto info = port.query_interface();
  if (!info) return describe_link_error(port.name(), info.error());
  CanLinkInfo link;
  link.info = info.value();
  link.kind = LinkKind::Can;
  link.kind_name = "can";
  const LinkVerdict verdict = check_can_link(port.name(), link, expected_bitrate);
  return verdict.error ? verdict.message : std::string();
}

CanioBusOptions make_canio_options(const CanioBusConfig& bus, std::span<const AxisConfig> axes,
                                   uint32_t period_us) {
  CanioBusOptions o;
  o.bus = bus;
  o.period_us = period_us;
  o.response_window_us = canio_timing(bus, axes.size(), period_us).window_us;
  for (std::size_t i = 0; i < axes.size(); ++i) {
    const AxisConfig& a = axes[i];
    CanioAxisPlan p;
    p.node = a.node;
    p.slot = a.slot;
    p.ids = canio_axis_ids(bus, a, i);
    p.module = a.module;
    p.name = a.name;
    o.axes.push_back(p);
  }
  return o;
}

CanioBus::CanioBus(CanioBusOptions options, std::unique_ptr<CanPort> cycle_port,
                   std::unique_ptr<CanPort> sdo_port)
    : options_(std::move(options)),
      cycle_port_(std::move(cycle_port)),
      sdo_port_(std::move(sdo_port)),
      sdo_mapping_(options_.bus.sdo_overrides),
      order_(options_.bus.little_endian ? ByteOrder::Little : ByteOrder::Big),
      track_(options_.axes.size()),
      axis_counters_(std::make_unique<CanioAxisCounters[]>(options_.axes.size())),
      clock_(&rt::now_ns),
      sdo_client_(int64_t{options_.bus.sdo_timeout_ms} * 1'000'000),
      axis_sdo_(options_.axes.size()),
      notes_(std::make_unique<NoteCell[]>(options_.axes.size())) {
  if (options_.axes.size() > kMaxCanioAxes)
    throw std::invalid_argument("canio: at most 64 axes per bus");
  for (const CanioAxisPlan& a : options_.axes) {
    if (node_index(a.node) < nodes_.size()) continue;
    NodeTrack t;
    t.node = a.node;
    const CanioNodeOptions no = canio_node_options(options_.bus, a.node);
    t.heartbeat_ms = no.heartbeat_ms;
    t.consumer_ns =
        int64_t{heartbeat_consumer_ms(no.heartbeat_ms, no.heartbeat_timeout_ms)} * 1'000'000;
    const std::array<const std::optional<uint32_t>*, 5> expected{
        &no.identity.device_type, &no.identity.vendor_id, &no.identity.product_code,
        &no.identity.revision_no, &no.identity.serial_no};
    for (std::size_t f = 0; f < expected.size(); ++f) {
      if (!*expected[f]) continue;
      t.identity_mask = static_cast<uint8_t>(t.identity_mask | (1U << f));
      t.identity_expected[f] = **expected[f];
    }
    t.identity_due = t.identity_mask != 0;
    t.identity_state =
        t.identity_mask != 0 ? NodeIdentityState::Pending : NodeIdentityState::Unchecked;
    nodes_.push_back(t);
  }
  node_counters_ = std::make_unique<CanioNodeCounters[]>(nodes_.size());
  for (std::size_t k = 0; k < nodes_.size(); ++k) {
    node_counters_[k].node = nodes_[k].node;
    publish_identity(k);
  }
  for (const CanioAxisPlan& a : options_.axes)
    axis_node_.push_back(static_cast<uint16_t>(node_index(a.node)));
  for (std::size_t i = 0; i < options_.axes.size(); ++i) {
    const auto axis = static_cast<uint16_t>(i);
    routes_.push_back({options_.axes[i].ids.input[0], axis, ObjectKind::Position});
    routes_.push_back({options_.axes[i].ids.input[1], axis, ObjectKind::Status});
    if (options_.assume_configured) {
      axis_counters_[i].configured.store(true);
      axis_counters_[i].state.store(CanioAxisState::Operational);
    }
  }
  std::sort(routes_.begin(), routes_.end(),
            [](const ObjectRoute& a, const ObjectRoute& b) { return a.id < b.id; });
}

CanioBus::~CanioBus() {
  stop();
}

CanInterfaceInfo CanioBus::interface_info() const {
  std::lock_guard lock(info_mutex_);
  return info_;
}

std::error_code CanioBus::start() {
  if (!options_.assume_configured && options_.bus.acyclic == CanAcyclicTransport::None) {
    // Function model 254 boots with EnDat disabled and the MTUs unset (datasheet §11.8.1.1,
    // §11.9.4.1): without acyclic access the module can never deliver a position.
    const CanioAxisPlan& a = options_.axes.front();
    start_error_ = "axis '" + a.name + "' (node " + std::to_string(a.node) +
                   "): canio.acyclic.transport is none, but under function model 254 the module "
                   "boots with EnDat disabled (EnDatMode 0) and OutputMTU/InputMTU unset; the "
                   "daemon must write them — configure transport canopen_sdo";
    return make_error_code(CanioBusError::kNoAcyclicTransport);
  }
  std::vector<CanIdFilter> ids;
  for (const ObjectRoute& r : routes_) ids.push_back({r.id, false});
  if (auto ec = cycle_port_->set_filters(ids)) {
    start_error_ = "CAN filters on " + std::string(cycle_port_->name()) + ": " + ec.message();
    return ec;
  }
  if (auto ec = cycle_port_->set_error_mask(kDefaultErrorMask)) {
    start_error_ = "CAN error frames on " + std::string(cycle_port_->name()) + ": " + ec.message();
    return ec;
  }
  if (sdo_port_) {
    // The node port: SDO answers, boot-up / heartbeat and EMCY of every node (never the cycle
    // port: they must not wake the response window).
    std::vector<CanIdFilter> sdo_ids;
    for (const NodeTrack& t : nodes_) {
      sdo_ids.push_back({kSdoResponseBase + t.node, false});
      sdo_ids.push_back({kErrorControlBase + t.node, false});
      if (kEmcyBase + t.node != options_.bus.sync_id)
        sdo_ids.push_back({kEmcyBase + t.node, false});
    }
    if (auto ec = sdo_port_->set_filters(sdo_ids)) {
      start_error_ = "CAN filters (SDO) on " + std::string(sdo_port_->name()) + ": " + ec.message();
      return ec;
    }
    (void)sdo_port_->set_error_mask(0);
  }
  if (auto info = cycle_port_->query_interface()) {
    if (info.value().restart_ms == 0 && !options_.bus.allow_manual_restart) {
      // Without restart-ms the kernel never restarts a controller after bus-off: the bus would
      // stay down until an administrator runs `ip link set … type can restart`.
      const std::string ifc(cycle_port_->name());
      start_error_ = "CAN interface '" + ifc +
                     "' has restart-ms 0: after a bus-off the controller would stay off until "
                     "restarted by hand; set an automatic restart: ip link set " +
                     ifc + " down && ip link set " + ifc + " type can bitrate " +
                     std::to_string(options_.bus.bitrate) + " restart-ms 100 && ip link set " +
                     ifc + " up (or accept it with canio.allow_manual_restart: true)";
      return make_error_code(CanError::kInterfaceDown);
    }
    std::lock_guard lock(info_mutex_);
    info_ = info.value();
  }
  // Every module is configured by the cycles that follow (step_sdo()); the cycle thread has not
  // started yet.
  if (!options_.assume_configured)
    for (AxisSdo& a : axis_sdo_) a.reconfigure = true;
  state_.store(BusState::Booting, std::memory_order_relaxed);
  return {};
}

void CanioBus::stop() noexcept {
  // NMT master: the nodes stop their process data but stay reachable over SDO (Enter
  // Pre-Operational; the next start configures and starts them again).
  if (state_.exchange(BusState::Down, std::memory_order_relaxed) != BusState::Down && sdo_port_ &&
      options_.bus.nmt == CanNmt::Start && !options_.assume_configured)
    for (const NodeTrack& t : nodes_)
      if (auto f = build_nmt(NmtCommand::EnterPreOperational, t.node)) (void)sdo_port_->send(*f);
}

const CanioBus::ObjectRoute* CanioBus::route(uint32_t id) const noexcept {
  auto it = std::lower_bound(routes_.begin(), routes_.end(), id,
                             [](const ObjectRoute& r, uint32_t v) { return r.id < v; });
  return it != routes_.end() && it->id == id ? &*it : nullptr;
}

void CanioBus::count_send(SendResult r) noexcept {
  if (r.sent()) return;
  if (r.status == SendStatus::QueueFull)
    single_writer_add(counters_.tx_queue_full);
  else
    single_writer_add(counters_.tx_failed);
}

bool CanioBus::bus_filtered(const CanFrame& f) noexcept {
  // A bus error (one per bit error, CAN_ERR_BUSERROR) that announces no state change: its
  // consequence arrives as a state change; never the cycle's business.
  if (!f.error || (f.id & err_class::kBusError) == 0) return false;
  auto ev = decode_error_frame(f);
  if (ev && ev.value().state_change()) return false;
  single_writer_add(counters_.bus_errors_filtered);
  return true;
}

void CanioBus::handle_frame(const CanFrame& f, Stamp where) noexcept {
  if (f.error) {
    if (bus_filtered(f)) return;
    single_writer_add(counters_.error_frames);  // the port has applied the state change
    return;
  }
  const ObjectRoute* r = f.extended ? nullptr : route(f.id);
  if (r == nullptr) {
    single_writer_add(counters_.unexpected_ids);
    return;
  }
  CanioAxisCounters& c = axis_counters_[r->axis];
  SyncPairing& p = track_[r->axis].pairing;
  if (f.rtr || f.dlc != kObjectBytes) {
    single_writer_add(c.wrong_length);
    if (where == Stamp::Window) p.seen(r->kind);
    return;
  }
  if (where == Stamp::Before) {
    single_writer_add(c.late_frames);
    p.late_before(r->kind);
    return;
  }
  if (where == Stamp::After) {
    single_writer_add(c.late_frames);
    p.late_after(r->kind);
    return;
  }
  CanObject bytes{};
  std::copy_n(f.data.begin(), kObjectBytes, bytes.begin());
  const uint8_t before = p.late_in_window();
  p.in_window(r->kind, bytes, f.rx_time_ns);
  if (p.late_in_window() != before) single_writer_add(c.late_frames);  // object 2 before object 1
}

bool CanioBus::window_complete(std::size_t n) const noexcept {
  for (std::size_t i = 0; i < n; ++i)
    if (!track_[i].pairing.ready()) return false;
  return true;
}

ExchangeResult CanioBus::exchange(std::span<AxisIo> axes, int64_t, uint64_t) noexcept {
  ExchangeResult result;
  single_writer_add(counters_.cycles);
  const std::size_t n = std::min(axes.size(), track_.size());
  for (std::size_t i = 0; i < n; ++i) axes[i].inputs_fresh = false;

  // Whatever is queued now arrived after the last cycle's deadline: late, never used (it settles
  // what the pairing still owes). Error frames among them move the port's state.
  for (;;) {
    const ReceiveResult rr = cycle_port_->receive(rx_, 0);
    if (rr.error) {
      single_writer_add(counters_.receive_errors);
      break;
    }
    for (std::size_t k = 0; k < rr.count; ++k) handle_frame(rx_[k], Stamp::Before);
    if (rr.count < rx_.size()) break;
  }

  const CanState can = cycle_port_->state();
  if (!can_transmit(can) && can != CanState::Unknown) {
    // Bus-off or down: nothing goes out; the kernel (restart-ms) or the virtual bus restarts the
    // controller, the error frame "restarted" brings the state back.
    if (!bus_was_down_) {
      bus_was_down_ = true;
      push_event({CanioNodeEventKind::BusOff, 0, clock_(), {}, 0});
    }
    single_writer_add(counters_.bus_off_cycles);
    if (can == CanState::BusOff && !bus_off_raised_) raise_incident(IncidentKind::BusOff);
    bus_off_raised_ = can == CanState::BusOff;
    state_.store(BusState::Error, std::memory_order_relaxed);
    result.bus_up = false;
    result.frames_lost = static_cast<uint32_t>(2 * n);
    step_sdo(clock_());  // timeouts run on; a request that cannot be sent fails as before
    return result;
  }

  if (bus_was_down_) {
    // Back from bus-off (or down): a node may have reset meanwhile and its boot-up was lost.
    // Every configured axis is trusted again only after a boot-up (configured anew), an
    // OPERATIONAL heartbeat, or a read-back of its configuration (the check after silence).
    bus_was_down_ = false;
    single_writer_add(counters_.bus_restarts);
    const int64_t t = clock_();
    push_event({CanioNodeEventKind::BusRestarted, 0, t, {}, 0});
    if (!options_.assume_configured)
      for (std::size_t k = 0; k < nodes_.size(); ++k) {
        node_down(k, false, t);
        nodes_[k].trust_by_heartbeat = nodes_[k].heartbeat_ms != 0;
      }
  }
  // Boot-up, heartbeat, EMCY and SDO answers that came in since the last cycle: a node that
  // announced a reset is down before this cycle's window.
  drain_node_port(clock_());
  bus_off_raised_ = false;
  for (std::size_t i = 0; i < n; ++i) track_[i].pairing.open();
  // The window opens before the SYNC is handed to the port: every answer to it is stamped later
  // (its end of frame follows the SYNC's on the wire).
  sync_tx_ns_ = clock_();
  deadline_ns_ = sync_tx_ns_ + static_cast<int64_t>(options_.response_window_us) * 1000;
  bool sync_sent = true;  // without SYNC the output objects trigger the answers
  if (options_.bus.sync_enabled) {
    CanFrame sync;
    sync.id = options_.bus.sync_id;
    sync.dlc = 0;
    const SendResult r = cycle_port_->send(sync);
    count_send(r);
    if (r.sent()) single_writer_add(counters_.sync_sent);
    sync_sent = r.sent();
  }
  for (std::size_t i = 0; i < n; ++i) {
    CanFrame out;
    out.id = options_.axes[i].ids.output;
    out.dlc = kObjectBytes;
    CanObject bytes{};
    pack_output_object(axes[i].outputs, bytes);
    std::copy(bytes.begin(), bytes.end(), out.data.begin());
    count_send(cycle_port_->send(out));
  }

  // This cycle's input objects, until every axis has its pair or the window ends. A receive that
  // returns nothing means the deadline has passed (or a test's clock stands still).
  int64_t last_rx = sync_tx_ns_;
  while (!window_complete(n)) {
    const ReceiveResult rr = cycle_port_->receive(rx_, deadline_ns_);
    for (std::size_t k = 0; k < rr.count; ++k) {
      const CanFrame& f = rx_[k];
      const int64_t t = f.rx_time_ns != 0 ? f.rx_time_ns : clock_();
      const Stamp where = t < sync_tx_ns_    ? Stamp::Before
                          : t > deadline_ns_ ? Stamp::After
                                             : Stamp::Window;
      if (where == Stamp::Window && !f.error) last_rx = std::max(last_rx, t);
      handle_frame(f, where);
    }
    if (rr.error) {
      single_writer_add(counters_.receive_errors);
      break;
    }
    if (rr.count == 0) break;
  }
  counters_.last_window_ns.store(last_rx - sync_tx_ns_, std::memory_order_relaxed);

  const int64_t now = clock_();
  const int64_t input_timeout_ns = static_cast<int64_t>(options_.bus.input_timeout_ms) * 1'000'000;
  for (std::size_t i = 0; i < n; ++i) {
    Track& t = track_[i];
    CanioAxisCounters& c = axis_counters_[i];
    const PairingVerdict verdict = t.pairing.close(sync_sent);
    if (t.pairing.surplus()) single_writer_add(c.duplicates);
    const bool whole = verdict == PairingVerdict::Whole;
    if (whole) {
      if (c.silent.load(std::memory_order_relaxed) &&
          c.last_sample_ns.load(std::memory_order_relaxed) != 0 && !options_.assume_configured) {
        // Back after silence: the node may have been power-cycled and lost its configuration
        // (EnDat disabled again). This axis publishes nothing until step_sdo() has checked it.
        c.configured.store(false, std::memory_order_release);
        axis_sdo_[i].reconfigure = true;
        // ... and may be another node on the cable: who it is is read again first.
        NodeTrack& node = nodes_[axis_node_[i]];
        node.identity_due = node.identity_mask != 0;
      }
      c.silent.store(false, std::memory_order_relaxed);
      c.last_sample_ns.store(now, std::memory_order_relaxed);
      single_writer_add(c.samples);
    } else {
      result.frames_lost += 2;
      if (verdict == PairingVerdict::Half)
        single_writer_add(c.half_samples);
      else if (verdict == PairingVerdict::Missing)
        single_writer_add(c.missing);
      else
        single_writer_add(c.unpaired);
      if (now - c.last_sample_ns.load(std::memory_order_relaxed) > input_timeout_ns)
        c.silent.store(true, std::memory_order_relaxed);
    }

    // Per-axis availability: only this axis is down while its module is being configured.
    if (!c.configured.load(std::memory_order_acquire)) {
      axes[i].axis_up = false;
      c.state.store(c.unconfigurable.load(std::memory_order_relaxed)
                        ? CanioAxisState::Unconfigurable
                    : identity_refused(axis_node_[i]) ? CanioAxisState::IdentityMismatch
                                                      : CanioAxisState::Configuring,
                    std::memory_order_relaxed);
      continue;
    }
    axes[i].axis_up = true;
    // PosCycle gate: after every (re)configuration a sample is new only once PosCycle moved
    // (under function model 254 the module boots with EnDat disabled: position 0, PosCycle
    // still).
    const uint32_t gen = c.generation.load(std::memory_order_acquire);
    if (gen != t.generation && !options_.assume_configured) {
      t.generation = gen;
      t.gated = true;
      t.gate_have = false;
    }
    ModuleInputs in = axes[i].inputs;
    if (whole) {
      (void)unpack_position_object(t.pairing.position(), order_, in);
      (void)unpack_status_object(t.pairing.status(), in);
    }
    if (whole && t.gated) {
      if (!t.gate_have) {
        t.gate_have = true;
        t.gate_pos_cycle = in.pos_cycle;
      } else if (in.pos_cycle != t.gate_pos_cycle) {
        t.gated = false;
      }
    }
    if (t.gated) {
      if (whole) single_writer_add(c.gated);
      // No process data at all since the configuration: the node has not started (yet).
      const bool starting =
          !t.gate_have && options_.bus.nmt == CanNmt::Start && !options_.assume_configured;
      c.state.store(starting ? CanioAxisState::Starting : CanioAxisState::AwaitingPosCycle,
                    std::memory_order_relaxed);
      continue;
    }
    if (!whole) {
      if (c.silent.load(std::memory_order_relaxed))
        c.state.store(CanioAxisState::Silent, std::memory_order_relaxed);
      continue;
    }
    c.state.store(CanioAxisState::Operational, std::memory_order_relaxed);
    axes[i].inputs = in;
    axes[i].inputs_fresh = true;
    axes[i].rx_time_ns = t.pairing.position_rx_ns();
  }
  // Register access and NMT between the windows: the SDO frames stay off the wire while this
  // cycle's objects are due (the bit budget counts one frame that may have started before a
  // SYNC).
  step_nmt(now);
  step_sdo(now);
  // The additional-information channels are read by SDO (step_sdo): a completed read is handed
  // over once.
  for (std::size_t i = 0; i < n; ++i) {
    axes[i].info_acyclic = true;
    axes[i].info_fresh = false;
    AxisSdo& a = axis_sdo_[i];
    if (!a.info_ready) continue;
    a.info_ready = false;
    axes[i].inputs.info_ok = a.info_ok;
    axes[i].inputs.info = a.info;
    axes[i].info_fresh = true;
  }
  // The bus cycles; which axis is usable is per axis (AxisIo::axis_up).
  state_.store(BusState::Operational, std::memory_order_relaxed);
  result.bus_up = true;
  return result;
}

}  // namespace ds1928::canio
