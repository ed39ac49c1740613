#include "powerlink/managing_node.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <string>

#include "powerlink/concise_dcf.hpp"
#include "powerlink/managing_node_cn.hpp"
#include "powerlink/pdo_image.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::powerlink {

std::string_view to_string(CnBootState s) noexcept {
  switch (s) {
    case CnBootState::kIdentify:
      return "identify";
    case CnBootState::kWaitPreOp2:
      return "wait_pre_operational_2";
    case CnBootState::kConfigure:
      return "configure";
    case CnBootState::kResetConfiguration:
      return "reset_configuration";
    case CnBootState::kWaitReadyToOperate:
      return "wait_ready_to_operate";
    case CnBootState::kWaitOperational:
      return "wait_operational";
    case CnBootState::kOperational:
      return "operational";
    case CnBootState::kReset:
      return "reset";
  }
  return "?";
}

std::string describe(const ObjectAccessFailure& f) {
  return object_name(f.index, f.subindex) + (f.read ? " read: " : " write: ") + f.error.message();
}

std::string describe(const IdentityMismatch& m) {
  const StandardObject* o = find_standard_object(m.index, m.subindex);
  const char* what = o ? o->meaning.data() : "?";
  std::array<char, 96> buf{};
  if (m.unreadable) {
    std::snprintf(buf.data(), buf.size(), " (%s): expected 0x%08X, cannot be read", what,
                  m.expected);
  } else {
    std::snprintf(buf.data(), buf.size(), " (%s): expected 0x%08X, found 0x%08X", what, m.expected,
                  m.found);
  }
  return object_name(m.index, m.subindex) + buf.data();
}

bool DllCounter::step(bool error, uint32_t threshold) noexcept {
  if (error) {
    ++events;
    value += 8;
  } else if (value > 0) {
    --value;
  }
  if (threshold == 0 || value < threshold) return false;
  value = 0;
  ++fired;
  return true;
}

struct ManagingNode::Handler {
  void (ManagingNode::*enter)(Cn&) noexcept;
  void (ManagingNode::*state)(Cn&, NmtState) noexcept;
  void (ManagingNode::*timeout)(Cn&) noexcept;  // nullptr: no timeout in this state
  bool reset_timer;                             // timeout uses reset_wait instead of boot step
};

// Indexed by CnBootState.
const ManagingNode::Handler ManagingNode::kHandlers[] = {
    {&ManagingNode::on_enter_identify, &ManagingNode::on_state_identify, nullptr, false},
    {&ManagingNode::on_enter_wait_preop2, &ManagingNode::on_state_wait_preop2,
     &ManagingNode::on_timeout_boot, false},
    {&ManagingNode::on_enter_configure, &ManagingNode::on_state_configure,
     &ManagingNode::on_timeout_boot, false},
    {&ManagingNode::on_enter_reset_configuration, &ManagingNode::on_state_reset,
     &ManagingNode::on_timeout_reset, true},
    {&ManagingNode::on_enter_ready, &ManagingNode::on_state_ready, &ManagingNode::on_timeout_boot,
     false},
    {&ManagingNode::on_enter_wait_operational, &ManagingNode::on_state_wait_operational,
     &ManagingNode::on_timeout_boot, false},
    {&ManagingNode::on_enter_operational, &ManagingNode::on_state_operational, nullptr, false},
    {&ManagingNode::on_enter_reset, &ManagingNode::on_state_reset, &ManagingNode::on_timeout_reset,
     true},
};

ManagingNode::ManagingNode(const MnConfig& config)
    : config_(config), mapping_(config.bus.sdo_overrides) {
  if (config_.bus.nmt.wait_not_active_ms > 0) mn_state_ = NmtState::kNotActive;
  status_view_.reserve(config_.bus.nodes.size());
  iso_list_.resize(config_.bus.nodes.size());
  prc_list_.resize(config_.bus.nodes.size());
  for (const PowerlinkNodeConfig& nc : config_.bus.nodes) {
    if (nc.node_id < 1 || nc.node_id > kNodeMaxCn)
      throw std::system_error(make_error_code(MnError::kNodeNotConfigured), "node id");
    auto cn = std::make_unique<Cn>();
    cn->cfg = nc;
    // Payload sizes the objects written to the CN define (NMT_CycleTiming /4,5 or its PDO
    // mappings), when the configuration gives none: the CN's IdentResponse predates its
    // configuration.
    std::vector<CdcEntry> written;
    for (const CnObjectWrite& w : nc.object_writes)
      written.push_back({w.index, w.subindex, w.data});
    if (!nc.preq_size || !nc.pres_size) {
      const ImageSizes sizes = image_sizes_from_objects(written);
      if (!cn->cfg.preq_size) cn->cfg.preq_size = sizes.preq_size;
      if (!cn->cfg.pres_size) cn->cfg.pres_size = sizes.pres_size;
    }
    cn->loss_threshold =
        nc.loss_of_pres_threshold.value_or(config_.bus.thresholds.loss_of_pres.value_or(
            default_loss_of_pres_threshold(config_.cycle_us)));
    status_view_.emplace_back();
    cn->st = &status_view_.back();
    cn->st->node = nc.node_id;
    cn->st->loss_of_pres_threshold = cn->loss_threshold;
    cn->st->prc_configured = nc.prc;
    std::vector<ModuleSpec> specs;
    for (const AxisConfig& a : config_.axes) {
      if (a.node != nc.node_id) continue;
      specs.push_back(
          {a.slot, a.module.input_mtu, a.module.output_mtu, a.pres_offset, a.preq_offset});
      for (const RegisterWrite& w : startup_writes(a.module))
        cn->boot_ops.push_back({a.slot, RegisterRequest{0, 0, w.reg, w.size, true, w.value}});
      // Named first: a range-for over .span() of a temporary would read it after its end.
      const InfoCommandWrites info = info_command_writes(a.module);
      for (const RegisterWrite& w : info.span())
        cn->boot_ops.push_back({a.slot, RegisterRequest{0, 0, w.reg, w.size, true, w.value}});
      // Datasheet §11.6.2.3: Rescan (EnDatAck bit 1) after EnDatMode, so the module reads the
      // identification of the encoder it now talks to (as on CAN-I/O).
      if (a.module.endat_enable)
        cn->boot_ops.push_back({a.slot, RegisterRequest{0, 0, reg::kEnDatAck, 1, true, 0x02}});
    }
    init_image(*cn, written, specs);
    // A configured payload size is what goes on the wire: every block must fit inside it.
    for (const ModuleMapping& m : cn->layout.mappings()) {
      const bool pres_out = nc.pres_size && pres_end(m) > *nc.pres_size;
      const bool preq_out = nc.preq_size && preq_end(m) > *nc.preq_size;
      if (pres_out || preq_out) {
        throw std::system_error(make_error_code(MnError::kModuleBlockOutsidePayload),
                                "process image of node " + std::to_string(nc.node_id) + ", " +
                                    (pres_out ? "PRes" : "PReq") + ": slot " +
                                    std::to_string(m.slot) + " ends past the configured " +
                                    (pres_out ? "pres_size " : "preq_size ") +
                                    std::to_string(pres_out ? *nc.pres_size : *nc.preq_size));
      }
    }
    // Identity read back by SDO where configured (as a configuration manager does), then the
    // cycle objects, then the configured objects in the order given.
    auto identity = [&](uint16_t index, uint8_t sub, const std::optional<uint32_t>& expected) {
      if (expected)
        cn->object_ops.push_back(
            {OpKind::kIdentityRead, index, sub, ValueSource::kData, *expected, 0, 0});
    };
    identity(obj::kDeviceType, 0, nc.device_type);
    identity(obj::kIdentity, 1, nc.vendor_id);
    identity(obj::kIdentity, 2, nc.product_code);
    identity(obj::kIdentity, 3, nc.revision_no);
    identity(obj::kIdentity, 4, nc.serial_no);
    if (nc.cycle_objects) {
      // Sizes as the table types them (NMT_CycleLen_U32, PReq/PResActPayloadLimit_U16).
      auto cycle_object = [&](uint16_t index, uint8_t sub, ValueSource source) {
        const StandardObject* o = find_standard_object(index, sub);
        cn->object_ops.push_back(
            {OpKind::kObjectWrite, index, sub, source, 0, 0, o ? type_size(o->type) : 4});
      };
      cycle_object(obj::kCycleLen, 0, ValueSource::kCycleUs);
      cycle_object(obj::kCycleTiming, obj::kCycleTimingPReqActPayload, ValueSource::kPreqSize);
      cycle_object(obj::kCycleTiming, obj::kCycleTimingPResActPayload, ValueSource::kPresSize);
    }
    for (const CnObjectWrite& w : nc.object_writes) {
      cn->object_ops.push_back({OpKind::kObjectWrite, w.index, w.subindex, ValueSource::kData, 0,
                                cn->object_data.size(), w.data.size()});
      cn->object_data.insert(cn->object_data.end(), w.data.begin(), w.data.end());
    }
    // A multiplexed CN checks its PReqs against NMT_CycleTiming.MultiplCycleCnt (0x1F98/7): the
    // PReq due in its slot of every multiplexed cycle. The same count to every multiplexed CN,
    // written last, so it is the polling the MN does whatever a concise DCF said.
    if (nc.multiplexed && config_.bus.multiplex_cycles > 1) {
      cn->object_ops.push_back({OpKind::kObjectWrite, obj::kCycleTiming,
                                obj::kCycleTimingMultiplCycleCnt, ValueSource::kData, 0,
                                cn->object_data.size(), 1});
      cn->object_data.push_back(config_.bus.multiplex_cycles);
    }
    Cn* raw = cn.get();
    SdoClientConfig sc;
    sc.node = nc.node_id;
    sc.own_mac = config_.mac;
    sc.timeout_ns = ms(config_.bus.sdo_timeout_ms);
    // The MN's own ASnd keeps to AsyncMTU: the cycle budget counts no longer one.
    sc.max_segment = sdo_segment_for_async_mtu(config_.bus.async_mtu);
    cn->sdo = std::make_unique<SdoClient>(
        sc, [raw](std::span<const uint8_t> f) { raw->push_outbox(f); },
        [this, raw](std::error_code ec, std::span<const uint8_t> d) { sdo_done(*raw, ec, d); });
    cns_.push_back(std::move(cn));
  }
  place_prc_outputs();
  assign_slots();
  for (auto& cn : cns_) enter(*cn, CnBootState::kIdentify);
}

void ManagingNode::assign_slots() {
  // One multiplexed cycle for the network (EPSG DS 301): MultiplCycleCnt cycles, each multiplexed
  // CN polled in its slot of them (given, else assigned: cycle_budget.hpp).
  const uint8_t cycles = config_.bus.multiplex_cycles;
  std::vector<MultiplexNode> mux;
  for (const auto& cn : cns_) {
    if (!cn->cfg.multiplexed) continue;
    const uint8_t slot = cn->cfg.multiplex_slot.value_or(0);
    if (cycles < 2 || slot > cycles || cn->cfg.prc)
      throw std::system_error(
          make_error_code(MnError::kNodeNotConfigured),
          "node " + std::to_string(cn->cfg.node_id) +
              (cn->cfg.prc ? ": a PollResponse Chaining node has no multiplexed slot"
                           : ": multiplexed slot " + std::to_string(slot) +
                                 " outside the multiplexed cycle of " + std::to_string(cycles) +
                                 " (multiplex_cycles)"));
    mux.push_back({cn->cfg.node_id, slot});
  }
  if (mux.empty()) return;
  assign_multiplex_slots(mux, cycles);
  mux_cycle_len_ = cycles;
  for (const MultiplexNode& m : mux) {
    Cn& cn = *find(m.node_id);
    cn.mux_slot = m.slot;
    cn.st->multiplex_slot = m.slot;
  }
}

ManagingNode::~ManagingNode() = default;

ManagingNode::Cn* ManagingNode::find(uint8_t node) noexcept {
  for (auto& cn : cns_)
    if (cn->cfg.node_id == node) return cn.get();
  return nullptr;
}
const ManagingNode::Cn* ManagingNode::find(uint8_t node) const noexcept {
  for (const auto& cn : cns_)
    if (cn->cfg.node_id == node) return cn.get();
  return nullptr;
}

std::span<const CnStatus> ManagingNode::nodes() const noexcept {
  return status_view_;
}
const CnStatus* ManagingNode::node(uint8_t id) const noexcept {
  const Cn* cn = find(id);
  return cn ? cn->st : nullptr;
}
const NodeImageLayout* ManagingNode::layout(uint8_t id) const noexcept {
  const Cn* cn = find(id);
  return cn ? &cn->layout : nullptr;
}
bool ManagingNode::all_operational() const noexcept {
  for (const auto& cn : cns_)
    if (cn->cfg.mandatory && cn->st->boot != CnBootState::kOperational) return false;
  return !cns_.empty();
}

uint64_t ManagingNode::net_time_us() const noexcept {
  return powerlink::net_time_us(relative_time_us_, config_.bus.nettime_offset_us);
}

// ---- NMT state table ----------------------------------------------------------------------------

void ManagingNode::enter(Cn& cn, CnBootState state) noexcept {
  cn.st->boot = state;
  cn.state_since_ns = now_ns_;
  // Bind the row before the call: GCC 12 instrumentation (-fsanitize=undefined) mis-reads a
  // pointer-to-member taken straight out of the array expression (false -Wuninitialized, bogus
  // index).
  const Handler& h = kHandlers[static_cast<int>(state)];
  (this->*h.enter)(cn);
}

void ManagingNode::reported_state(Cn& cn, NmtState s) noexcept {
  cn.st->nmt = s;
  const Handler& h = kHandlers[static_cast<int>(cn.st->boot)];  // bound first: see enter()
  (this->*h.state)(cn, s);
}

void ManagingNode::reset_node(Cn& cn, std::error_code reason) noexcept {
  cn.st->last_error = reason;
  cn.st->last_reset_reason = reason;
  enter(cn, CnBootState::kReset);
}

void ManagingNode::queue_nmt(Cn& cn, NmtCommandId command) noexcept {
  std::array<uint8_t, kMinFrameSize> frame{};
  auto len = build_nmt_command(frame, asnd_header(config_.mac, kNodeMn, cn.cfg.node_id),
                               {static_cast<uint8_t>(command), {}});
  if (len) cn.push_outbox(std::span<const uint8_t>(frame.data(), *len));
}

void ManagingNode::on_enter_identify(Cn& cn) noexcept {
  cn.st->in_isochronous = false;
  cn.st->identified = false;
  cn.st->prc = false;
  cn.prc_step = PrcStep::kOff;
  cn.prc_wait = false;
}
void ManagingNode::on_state_identify(Cn&, NmtState) noexcept {}

void ManagingNode::on_enter_wait_preop2(Cn& cn) noexcept {
  cn.last_status_request = 0;
}
void ManagingNode::on_state_wait_preop2(Cn& cn, NmtState s) noexcept {
  if (s == NmtState::kPreOperational2 && full_cycle()) {
    enter(cn, CnBootState::kConfigure);
  } else if (s == NmtState::kReadyToOperate || s == NmtState::kOperational) {
    // Booted by someone else (or before an MN restart): start it over to configure it.
    reset_node(cn, make_error_code(MnError::kNodeNotOperational));
  }
}

void ManagingNode::on_enter_configure(Cn& cn) noexcept {
  // Two passes when there is something to write (EPSG DS 301's configuration download): the
  // writes, then NMTResetConfiguration (the CN takes the objects on re-entering its boot), then
  // this step again without writes, in which a PRC node is chained. A PRC node joins the
  // isochronous phase by its SyncRequests only (managing_node_prc.cpp): during the writes it gets
  // no PReq.
  const bool writing = !cn.config_applied && (!cn.object_ops.empty() || !cn.boot_ops.empty());
  cn.st->in_isochronous = !uses_prc(cn);
  cn.prc_step = uses_prc(cn) && !writing ? PrcStep::kMeasurePredecessor : PrcStep::kOff;
  cn.prc_failures = 0;
  cn.prc_wait = false;
  cn.object_next = writing ? 0 : cn.object_ops.size();
  cn.boot_next = writing ? 0 : cn.boot_ops.size();
  if (writing) {
    cn.st->last_failure_count = 0;
    cn.written = 0;
  }
  cn.configuring = true;
  start_next_sdo(cn);
}

void ManagingNode::on_enter_reset_configuration(Cn& cn) noexcept {
  // The CN goes through RESET_CONFIGURATION to NOT_ACTIVE and answers no PReq until it is in
  // PRE_OPERATIONAL_2 again: out of the isochronous phase, identified again after reset_wait
  // (its IdentResponse then reports the payload sizes it took).
  cn.st->in_isochronous = false;
  cn.st->identified = false;
  cn.config_applied = true;
  cn.sdo_wait_answer = false;
  cn.sdo->reset();  // the CN's SDO server forgets its connection; the next transfer reopens it
  ++cn.st->configuration_resets;
  queue_nmt(cn, NmtCommandId::kResetConfiguration);
}
void ManagingNode::on_state_configure(Cn& cn, NmtState s) noexcept {
  if (s == NmtState::kNotActive || s == NmtState::kPreOperational1)
    reset_node(cn, make_error_code(MnError::kNodeNotOperational));
}

void ManagingNode::on_enter_ready(Cn& cn) noexcept {
  queue_nmt(cn, NmtCommandId::kEnableReadyToOperate);
}
void ManagingNode::on_state_ready(Cn& cn, NmtState s) noexcept {
  if (s == NmtState::kReadyToOperate && (mn_state_ == NmtState::kOperational))
    enter(cn, CnBootState::kWaitOperational);
  else if (s == NmtState::kNotActive || s == NmtState::kPreOperational1)
    reset_node(cn, make_error_code(MnError::kNodeNotOperational));
}

void ManagingNode::on_enter_wait_operational(Cn& cn) noexcept {
  queue_nmt(cn, NmtCommandId::kStartNode);
}
void ManagingNode::on_state_wait_operational(Cn& cn, NmtState s) noexcept {
  if (s == NmtState::kOperational)
    enter(cn, CnBootState::kOperational);
  else if (s == NmtState::kNotActive || s == NmtState::kPreOperational1)
    reset_node(cn, make_error_code(MnError::kNodeNotOperational));
}

void ManagingNode::on_enter_operational(Cn& cn) noexcept {
  ++cn.st->boots;
  // A PRC fall-back stays said while it lasts (the node runs, but not as configured).
  cn.st->last_error =
      cn.st->prc_fallback ? make_error_code(MnError::kPrcNotSupported) : std::error_code{};
}
void ManagingNode::on_state_operational(Cn& cn, NmtState s) noexcept {
  // A CN that falls back (power-cycle, own error) is booted again from the start.
  if (s != NmtState::kOperational) reset_node(cn, make_error_code(MnError::kNodeNotOperational));
}

void ManagingNode::on_enter_reset(Cn& cn) noexcept {
  // NMTResetNode: the CN restores its stored communication objects; they are written again.
  cn.config_applied = false;
  // The CN may be another one when it comes back: its own mapping is read again.
  if (cn.read_mapping) cn.map_read = MapRead::kTpdo;
  cn.map_sub = cn.map_count = 0;
  cn.st->in_isochronous = false;
  cn.st->identified = false;
  cn.st->prc = false;
  cn.prc_step = PrcStep::kOff;
  cn.prc_wait = false;
  ++cn.st->resets;
  cn.outbox_count = 0;
  cn.configuring = false;
  cn.sdo_wait_answer = false;
  cn.rs = 0;
  cn.sdo->reset();
  // Queued register requests cannot be served by a node that restarts.
  while (cn.ops_count > 0) {
    const RegisterRequest& op = cn.ops[cn.ops_head].request;
    push_result({op.tag, make_error_code(SdoError::kConnectionLost), 0});
    cn.ops_head = (cn.ops_head + 1) % kOpQueueDepth;
    --cn.ops_count;
  }
  queue_nmt(cn, NmtCommandId::kResetNode);
}
void ManagingNode::on_state_reset(Cn&, NmtState) noexcept {}
void ManagingNode::on_timeout_reset(Cn& cn) noexcept {
  enter(cn, CnBootState::kIdentify);
}
void ManagingNode::on_timeout_boot(Cn& cn) noexcept {
  reset_node(cn, make_error_code(MnError::kBootStepTimeout));
}

// ---- Cycle
// ----------------------------------------------------------------------------------------

void ManagingNode::begin_cycle(int64_t now_ns) noexcept {
  if (start_ns_ < 0) {
    start_ns_ = now_ns;
    mn_state_since_ns_ = now_ns;
  }
  now_ns_ = now_ns;
  soa_service_ = RequestedService::kNone;
  soa_target_ = 0;
  awaiting_asnd_ = false;
  mn_asnd_from_ = nullptr;
  prc_sync_from_ = nullptr;
  iso_count_ = 0;
  prc_count_ = 0;
  // SoC MC: toggled when the last cycle of a multiplexed cycle has ended (EPSG DS 301), so a CN
  // can tell where the multiplexed cycle starts.
  if (mux_cycle_len_ > 1 && counters_.cycles > 0 && counters_.cycles % mux_cycle_len_ == 0)
    mc_flag_ = !mc_flag_;
  for (auto& cn : cns_) {
    cn->polled = cn->pres_seen = cn->pres_usable = cn->timed_out = cn->late = false;
    cn->outputs_written = false;
  }
  // The continuous CNs first, then the multiplexed CNs of this cycle's slot (EPSG DS 301); the
  // multiplexed cycle's first cycle is slot 1.
  const uint64_t slot = counters_.cycles % mux_cycle_len_ + 1;
  for (const bool multiplexed : {false, true}) {
    for (auto& cn : cns_) {
      if (!full_cycle() || !cn->st->in_isochronous) continue;
      if ((cn->mux_slot != 0) != multiplexed) continue;
      if (cn->st->prc) {
        prc_list_[prc_count_++] = cn->cfg.node_id;
        continue;
      }
      if (multiplexed && cn->mux_slot != slot) continue;
      iso_list_[iso_count_++] = cn->cfg.node_id;
    }
  }
  update_prc_slot();
}

void ManagingNode::stamp_soc(int64_t send_ns, NetTime net_time) noexcept {
  net_time_ = net_time;
  const uint64_t rel =
      send_ns > start_ns_ ? static_cast<uint64_t>((send_ns - start_ns_) / 1000) : 0;
  if (rel >= relative_time_us_) {
    relative_time_us_ = rel;
    soc_time_ns_ = send_ns;
  } else {
    // A clock that went backwards: keep RelativeTime and pair it with the instant it denotes, so
    // the NetTimeRef stays consistent with what the SoC carries.
    soc_time_ns_ = start_ns_ + static_cast<int64_t>(relative_time_us_) * 1000;
  }
}

bool ManagingNode::full_cycle() const noexcept {
  return mn_state_ != NmtState::kPreOperational1 && mn_state_ != NmtState::kNotActive;
}

void ManagingNode::not_active_cycle() noexcept {
  update_mn_state();
}

std::span<const uint8_t> ManagingNode::isochronous_nodes() const noexcept {
  return {iso_list_.data(), iso_count_};
}

Result<std::size_t> ManagingNode::build_soc(std::span<uint8_t> out) const noexcept {
  Soc soc;
  soc.multiplexed_cycle_completed = mc_flag_;
  soc.net_time = net_time_;
  soc.relative_time_us = relative_time_us_;
  return powerlink::build_soc(out, soc_header(config_.mac), soc);
}

std::span<uint8_t> ManagingNode::preq_payload(uint8_t node) noexcept {
  Cn* cn = find(node);
  if (!cn) return {};
  if (cn->st->prc && cn->st->prc_outputs_size > 0)
    return {pres_mn_.data() + cn->st->prc_outputs_offset, cn->st->prc_outputs_size};
  return {cn->preq.data(), cn->st->preq_size};
}

std::span<const uint8_t> ManagingNode::pres_payload(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  if (!cn) return {};
  return {cn->pres.data(), cn->st->last_pres_size};
}

bool ManagingNode::pres_fresh(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  return cn && cn->pres_usable;
}

bool ManagingNode::pres_seen(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  return cn && cn->pres_seen;
}

uint32_t ManagingNode::pres_timeout_us(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  return cn ? cn->cfg.pres_timeout_us : 0;
}

void ManagingNode::outputs_written(uint8_t node) noexcept {
  if (Cn* cn = find(node)) cn->outputs_written = true;
}

Result<std::size_t> ManagingNode::build_preq(uint8_t node, std::span<uint8_t> out) noexcept {
  Cn* cn = find(node);
  if (!cn) return MnError::kNodeNotConfigured;
  cn->polled = true;
  PReq preq;
  // RD: the outputs this PReq carries are valid (EPSG DS 301): the MN is OPERATIONAL and wrote
  // them this cycle. A CN takes no outputs from a PReq with RD = 0.
  preq.ready = mn_state_ == NmtState::kOperational && cn->outputs_written;
  preq.multiplexed_slot = cn->mux_slot != 0;
  preq.exception_acknowledge = cn->errsig.exception_acknowledge();
  preq.payload = std::span<const uint8_t>(cn->preq.data(), cn->st->preq_size);
  return powerlink::build_preq(out, preq_header(config_.mac, cn->st->mac, node), preq);
}

void ManagingNode::on_pres_timeout(uint8_t node) noexcept {
  if (Cn* cn = find(node)) cn->timed_out = true;
}

std::error_code ManagingNode::on_frame(std::span<const uint8_t> bytes) noexcept {
  auto frame = parse_frame(bytes);
  if (!frame) {
    ++counters_.invalid_frames;
    return frame.error();
  }
  if (is_short_frame(bytes.size())) ++counters_.short_frames;
  const FrameHeader& h = frame->header;
  if (const PRes* pres = std::get_if<PRes>(&frame->message)) {
    Cn* cn = find(h.src_node);
    if (!cn) {
      ++counters_.unexpected_frames;
      return {};
    }
    if (!cn->polled) {
      // Not asked this cycle (yet): the late answer to an earlier PReq.
      ++cn->st->stale_pres_dropped;
      cn->late = true;
      return {};
    }
    if (cn->timed_out || cn->pres_seen) {
      cn->late = true;
      return {};
    }
    handle_pres(*cn, *pres, bytes);
    return {};
  }
  if (const Asnd* asnd = std::get_if<Asnd>(&frame->message)) {
    handle_asnd(h, *asnd);
    return {};
  }
  // SoC/PReq/SoA from someone else: another MN on the segment.
  ++counters_.unexpected_frames;
  ++counters_.foreign_mn_frames;
  counters_.foreign_mn_mac = h.src_mac;
  counters_.foreign_mn_frame = h.type;
  if (mn_state_ == NmtState::kNotActive) counters_.foreign_mn_at_start = true;
  return {};
}

void ManagingNode::handle_pres(Cn& cn, const PRes& pres, std::span<const uint8_t>) noexcept {
  cn.pres_seen = true;
  ++cn.st->pres_received;
  cn.rs = pres.request_count;
  cn.pr = pres.priority;
  note_exception_new(cn, pres.exception_new);
  const std::size_t size = pres.payload.size();
  cn.st->last_pres_size = static_cast<uint16_t>(size);
  std::memcpy(cn.pres.data(), pres.payload.data(), size);
  // Until its configuration is written a CN's PRes need not have the configured size yet
  // (its mapping is among the objects written): counted from then on.
  const bool configured = cn.st->boot == CnBootState::kWaitReadyToOperate ||
                          cn.st->boot == CnBootState::kWaitOperational ||
                          cn.st->boot == CnBootState::kOperational;
  if (size != cn.st->pres_size && configured) {
    ++cn.st->pres_size_mismatches;
    cn.st->last_error = make_error_code(MnError::kPresSizeMismatch);
  }
  // RD = 0: the CN's TPDO data is not ready (openPOWERLINK's pdok.c drops such a PRes's RPDO
  // too). Before OPERATIONAL every CN sends RD = 0; counted only from a CN that says it runs.
  cn.st->pres_ready = pres.ready;
  if (!pres.ready && pres.nmt_state == NmtState::kOperational) ++cn.st->pres_not_ready;
  // Inputs are usable when the modules' bytes are all there, whatever else the CN appends, and
  // the CN says they are valid.
  cn.pres_usable = pres.ready && size >= cn.layout.pres_size;
  reported_state(cn, pres.nmt_state);
}

void ManagingNode::update_mn_state() noexcept {
  if (mn_state_ == NmtState::kNotActive) {
    // Another MN heard while listening: stay NOT_ACTIVE (openPOWERLINK's MN freezes there too,
    // nmtk.c doStateMsNotActive()); two MNs' SoCs on one segment would wreck both cycles.
    if (!counters_.foreign_mn_at_start &&
        now_ns_ - mn_state_since_ns_ >= ms(config_.bus.nmt.wait_not_active_ms)) {
      mn_state_ = NmtState::kPreOperational1;
      mn_state_since_ns_ = now_ns_;
    }
    return;
  }
  if (mn_state_ == NmtState::kPreOperational1) {
    bool all_identified = !cns_.empty();
    for (const auto& cn : cns_)
      if (cn->cfg.mandatory && !cn->st->identified) all_identified = false;
    if (all_identified || now_ns_ - mn_state_since_ns_ >= ms(config_.bus.nmt.pre_op1_timeout_ms)) {
      mn_state_ = NmtState::kPreOperational2;
      mn_state_since_ns_ = now_ns_;
    }
    return;
  }
  if (mn_state_ == NmtState::kPreOperational2) {
    // OPERATIONAL (and RD in the PReq) only once every mandatory CN has confirmed
    // READY_TO_OPERATE: NMTEnableReadyToOperate sent is not enough.
    bool ready = !cns_.empty();
    for (const auto& cn : cns_) {
      const CnBootState b = cn->st->boot;
      const bool confirmed =
          (b == CnBootState::kWaitReadyToOperate && cn->st->nmt == NmtState::kReadyToOperate) ||
          b == CnBootState::kWaitOperational || b == CnBootState::kOperational;
      if (cn->cfg.mandatory && !confirmed) ready = false;
    }
    if (ready) {
      mn_state_ = NmtState::kOperational;
      mn_state_since_ns_ = now_ns_;
    }
  }
  if (mn_state_ == NmtState::kOperational) {
    for (auto& cn : cns_)
      if (cn->st->boot == CnBootState::kWaitReadyToOperate &&
          cn->st->nmt == NmtState::kReadyToOperate)
        enter(*cn, CnBootState::kWaitOperational);
  }
}

void ManagingNode::end_cycle(bool cycle_time_exceeded) noexcept {
  const DllThresholds& th = config_.bus.thresholds;
  // Reaction to these two: counted and shown in status (fired); the cycle goes on.
  (void)counters_.cycle_time_exceeded.step(cycle_time_exceeded, th.cycle_time_exceeded);
  for (auto& p : cns_) {
    Cn& cn = *p;
    // Every cycle counts (EPSG DS 301): −1 in each cycle without the error, also in those that
    // did not poll a multiplexed CN, or sparse losses of a CN polled every n-th cycle would add
    // up to a reset.
    if (cn.st->in_isochronous || cn.polled) {
      const bool lost = cn.polled && !cn.pres_seen;
      if (cn.st->loss_of_pres.step(lost, cn.loss_threshold)) {
        reset_node(cn, make_error_code(MnError::kLossOfPresThreshold));
      }
      (void)cn.st->late_pres.step(cn.late, th.late_pres);
    }
    cn.sdo->tick(now_ns_);
    const Handler& h = kHandlers[static_cast<int>(cn.st->boot)];
    if (h.timeout) {
      const int64_t limit = h.reset_timer ? ms(config_.bus.nmt.reset_wait_ms)
                                          : ms(config_.bus.nmt.boot_step_timeout_ms);
      if (now_ns_ - cn.state_since_ns >= limit) (this->*h.timeout)(cn);
    }
  }
  update_mn_state();
  ++counters_.cycles;
}

}  // namespace ds1928::powerlink
