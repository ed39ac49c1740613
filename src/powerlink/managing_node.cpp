#include "powerlink/managing_node.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <string>

#include "core/register_catalogue.hpp"
#include "powerlink/concise_dcf.hpp"

namespace ds1928::powerlink {

std::string_view to_string(CnBootState s) noexcept {
  switch (s) {
    case CnBootState::kIdentify:
      return "identify";
    case CnBootState::kWaitPreOp2:
      return "wait_pre_operational_2";
    case CnBootState::kConfigure:
      return "configure";
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
  const char* what = m.index == 0x1000 ? "device type"
                     : m.subindex == 1 ? "vendor id"
                     : m.subindex == 2 ? "product code"
                     : m.subindex == 3 ? "revision number"
                                       : "serial number";
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

namespace {
constexpr std::size_t kOutboxDepth = 4;
constexpr std::size_t kOpQueueDepth = 32;

// What an SDO transfer of a CN is for.
enum class OpKind : uint8_t {
  kRegister,      // a module register (boot configuration or a client's request)
  kIdentityRead,  // 0x1000 / 0x1018 read back and compared
  kObjectWrite,   // an object of the CN's configuration (concise DCF, sdo_writes, cycle objects)
};
// Where an object write's value comes from: fixed bytes, or what is known only at boot.
enum class ValueSource : uint8_t { kData, kCycleUs, kPreqSize, kPresSize };
struct ObjectOp {
  OpKind kind = OpKind::kObjectWrite;
  uint16_t index = 0;
  uint8_t subindex = 0;
  ValueSource source = ValueSource::kData;
  uint32_t expected = 0;  // identity read
  std::size_t data_offset = 0;
  std::size_t data_size = 0;
};
}  // namespace

struct ManagingNode::Cn {
  PowerlinkNodeConfig cfg;
  CnStatus* st = nullptr;
  NodeImageLayout layout;
  std::array<uint8_t, kMaxIsoPayload> preq{};
  std::array<uint8_t, kMaxIsoPayload> pres{};
  bool polled = false;          // PReq sent this cycle
  uint32_t loss_threshold = 0;  // DLL_MNCNLossPResThreshold (0x1C09) in effect
  bool pres_seen = false;       // its PRes arrived this cycle
  bool pres_usable = false;     // ... with a payload the layout fits in
  bool timed_out = false;       // the driver gave up waiting for it this cycle
  bool late = false;            // a PRes came after its timeout
  int64_t state_since_ns = 0;
  uint64_t last_status_request = 0;
  uint8_t rs = 0;  // CN's pending async requests (RS) and their priority (PR)
  uint8_t pr = 0;
  bool sdo_wait_answer = false;
  // Frames the MN sends to this CN in the async phase (NMT commands, SDO).
  std::array<std::array<uint8_t, kMaxFrameSize>, kOutboxDepth> outbox{};
  std::array<std::size_t, kOutboxDepth> outbox_len{};
  std::size_t outbox_head = 0;
  std::size_t outbox_count = 0;
  uint32_t outbox_overflows = 0;
  std::unique_ptr<SdoClient> sdo;
  // Boot step "configure", built once: identity reads and object writes first, then the module
  // registers. Object values live in object_data.
  std::vector<ObjectOp> object_ops;
  std::vector<uint8_t> object_data;
  std::size_t object_next = 0;
  std::vector<SdoRegisterOp> boot_ops;  // module configuration
  std::size_t boot_next = 0;
  OpKind op_kind = OpKind::kRegister;
  std::array<uint8_t, 4> op_value{};  // value of a ValueSource other than kData
  // Exception signalling: EN changed since the last acknowledgement; ER still to be sent.
  bool exception_pending = false;
  bool exception_reset_due = false;
  bool configuring = false;
  std::array<SdoRegisterOp, kOpQueueDepth> ops{};
  std::size_t ops_head = 0;
  std::size_t ops_count = 0;
  bool op_active = false;
  bool op_internal = false;
  SdoRegisterOp current{};

  void push_outbox(std::span<const uint8_t> frame) noexcept {
    if (outbox_count == kOutboxDepth || frame.size() > kMaxFrameSize) {
      ++outbox_overflows;
      return;
    }
    const std::size_t i = (outbox_head + outbox_count) % kOutboxDepth;
    std::memcpy(outbox[i].data(), frame.data(), frame.size());
    outbox_len[i] = frame.size();
    ++outbox_count;
  }
};

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
  status_view_.reserve(config_.bus.nodes.size());
  iso_list_.resize(config_.bus.nodes.size());
  for (const PowerlinkNodeConfig& nc : config_.bus.nodes) {
    if (nc.node_id < 1 || nc.node_id > kNodeMaxCn)
      throw std::system_error(make_error_code(MnError::kNodeNotConfigured), "node id");
    auto cn = std::make_unique<Cn>();
    cn->cfg = nc;
    // Payload sizes the objects written to the CN define (0x1F98/4,5 or its PDO mappings), when
    // the configuration gives none: the CN's IdentResponse predates its configuration.
    if (!nc.preq_size || !nc.pres_size) {
      std::vector<CdcEntry> written;
      for (const CnObjectWrite& w : nc.object_writes)
        written.push_back({w.index, w.subindex, w.data});
      const ImageSizes sizes = image_sizes_from_objects(written);
      if (!cn->cfg.preq_size) cn->cfg.preq_size = sizes.preq_size;
      if (!cn->cfg.pres_size) cn->cfg.pres_size = sizes.pres_size;
    }
    cn->loss_threshold =
        nc.loss_of_pres_threshold.value_or(config_.bus.thresholds.loss_of_pres.value_or(
            default_loss_of_pres_threshold(config_.cycle_us)));
    if (nc.multiplex > 1)
      mux_cycle_len_ = std::min<uint64_t>(std::lcm(mux_cycle_len_, uint64_t{nc.multiplex}), 4096);
    status_view_.emplace_back();
    cn->st = &status_view_.back();
    cn->st->node = nc.node_id;
    cn->st->loss_of_pres_threshold = cn->loss_threshold;
    std::vector<ModuleSpec> specs;
    for (const AxisConfig& a : config_.axes) {
      if (a.node != nc.node_id) continue;
      specs.push_back(
          {a.slot, a.module.input_mtu, a.module.output_mtu, a.pres_offset, a.preq_offset});
      for (const RegisterWrite& w : startup_writes(a.module))
        cn->boot_ops.push_back({0, nc.node_id, a.slot, w.reg, w.size, true, w.value});
    }
    LayoutIssue issue;
    auto layout = make_layout(specs, &issue);
    if (!layout) {
      std::string what = "process image of node " + std::to_string(nc.node_id) + ", " +
                         (issue.in_preq ? "PReq" : "PRes") + ": slot " + std::to_string(issue.slot);
      if (issue.other_slot != 0) what += " and slot " + std::to_string(issue.other_slot);
      throw std::system_error(layout.error(), what);
    }
    // A configured payload size is what goes on the wire: every block must fit inside it.
    for (const ModuleMapping& m : layout->mappings()) {
      const bool pres_out =
          nc.pres_size && m.pres_offset + pres_module_size(m.input_mtu) > *nc.pres_size;
      const bool preq_out =
          nc.preq_size && m.preq_offset + preq_module_size(m.output_mtu) > *nc.preq_size;
      if (pres_out || preq_out) {
        throw std::system_error(make_error_code(MnError::kModuleBlockOutsidePayload),
                                "process image of node " + std::to_string(nc.node_id) + ", " +
                                    (pres_out ? "PRes" : "PReq") + ": slot " +
                                    std::to_string(m.slot) + " ends past the configured " +
                                    (pres_out ? "pres_size " : "preq_size ") +
                                    std::to_string(pres_out ? *nc.pres_size : *nc.preq_size));
      }
    }
    cn->layout = *layout;
    // Identity read back by SDO where configured (as a configuration manager does), then the
    // cycle objects, then the configured objects in the order given.
    auto identity = [&](uint16_t index, uint8_t sub, const std::optional<uint32_t>& expected) {
      if (expected)
        cn->object_ops.push_back(
            {OpKind::kIdentityRead, index, sub, ValueSource::kData, *expected, 0, 0});
    };
    identity(0x1000, 0, nc.device_type);
    identity(0x1018, 1, nc.vendor_id);
    identity(0x1018, 2, nc.product_code);
    identity(0x1018, 3, nc.revision_no);
    identity(0x1018, 4, nc.serial_no);
    if (nc.cycle_objects) {
      cn->object_ops.push_back({OpKind::kObjectWrite, 0x1006, 0, ValueSource::kCycleUs, 0, 0, 4});
      cn->object_ops.push_back({OpKind::kObjectWrite, 0x1F98, 4, ValueSource::kPreqSize, 0, 0, 2});
      cn->object_ops.push_back({OpKind::kObjectWrite, 0x1F98, 5, ValueSource::kPresSize, 0, 0, 2});
    }
    for (const CnObjectWrite& w : nc.object_writes) {
      cn->object_ops.push_back({OpKind::kObjectWrite, w.index, w.subindex, ValueSource::kData, 0,
                                cn->object_data.size(), w.data.size()});
      cn->object_data.insert(cn->object_data.end(), w.data.begin(), w.data.end());
    }
    Cn* raw = cn.get();
    SdoClientConfig sc;
    sc.node = nc.node_id;
    sc.own_mac = config_.mac;
    sc.timeout_ns = ms(config_.bus.sdo_timeout_ms);
    cn->sdo = std::make_unique<SdoClient>(
        sc, [raw](std::span<const uint8_t> f) { raw->push_outbox(f); },
        [this, raw](std::error_code ec, std::span<const uint8_t> d) { sdo_done(*raw, ec, d); });
    cns_.push_back(std::move(cn));
  }
  for (auto& cn : cns_) enter(*cn, CnBootState::kIdentify);
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
  cn.st->in_isochronous = true;
  cn.object_next = 0;
  cn.st->last_failure_count = 0;
  cn.boot_next = 0;
  cn.configuring = true;
  start_next_sdo(cn);
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
  cn.st->last_error = {};
}
void ManagingNode::on_state_operational(Cn& cn, NmtState s) noexcept {
  // A CN that falls back (power-cycle, own error) is booted again from the start.
  if (s != NmtState::kOperational) reset_node(cn, make_error_code(MnError::kNodeNotOperational));
}

void ManagingNode::on_enter_reset(Cn& cn) noexcept {
  cn.st->in_isochronous = false;
  cn.st->identified = false;
  ++cn.st->resets;
  cn.outbox_count = 0;
  cn.configuring = false;
  cn.sdo_wait_answer = false;
  cn.rs = 0;
  cn.sdo->reset();
  // Queued register requests cannot be served by a node that restarts.
  while (cn.ops_count > 0) {
    const SdoRegisterOp& op = cn.ops[cn.ops_head];
    if (results_count_ < results_.size()) {
      results_[(results_head_ + results_count_++) % results_.size()] = {
          op.tag, make_error_code(SdoError::kConnectionLost), 0};
    }
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

// ---- SDO
// ------------------------------------------------------------------------------------------

bool ManagingNode::submit(const SdoRegisterOp& op) noexcept {
  Cn* cn = find(op.node);
  if (!cn || cn->ops_count == kOpQueueDepth) return false;
  cn->ops[(cn->ops_head + cn->ops_count) % kOpQueueDepth] = op;
  ++cn->ops_count;
  start_next_sdo(*cn);
  return true;
}

bool ManagingNode::can_submit(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  return cn != nullptr && cn->ops_count < kOpQueueDepth;
}

bool ManagingNode::poll(SdoRegisterResult& out) noexcept {
  if (results_count_ == 0) return false;
  out = results_[results_head_];
  results_head_ = (results_head_ + 1) % results_.size();
  --results_count_;
  return true;
}

void ManagingNode::start_next_sdo(Cn& cn) noexcept {
  while (!cn.op_active) {
    const CnBootState b = cn.st->boot;
    if (b == CnBootState::kIdentify || b == CnBootState::kReset) return;
    if (cn.configuring && cn.object_next < cn.object_ops.size()) {
      start_object_op(cn);
      continue;
    }
    if (cn.configuring && cn.boot_next < cn.boot_ops.size()) {
      cn.current = cn.boot_ops[cn.boot_next];
      cn.op_internal = true;
      cn.op_kind = OpKind::kRegister;
    } else if (cn.configuring) {
      cn.configuring = false;
      enter(cn, CnBootState::kWaitReadyToOperate);
      continue;
    } else if (cn.ops_count > 0 && b != CnBootState::kWaitPreOp2) {
      cn.current = cn.ops[cn.ops_head];
      cn.ops_head = (cn.ops_head + 1) % kOpQueueDepth;
      --cn.ops_count;
      cn.op_internal = false;
      cn.op_kind = OpKind::kRegister;
    } else {
      return;
    }
    const auto object = mapping_.object_for(cn.current.slot, cn.current.reg);
    if (!object) {
      sdo_done(cn, make_error_code(SdoError::kNoMapping), {});
      continue;
    }
    cn.op_active = true;
    std::error_code ec;
    if (cn.current.write) {
      std::array<uint8_t, 4> bytes{};
      store_le32(bytes.data(), cn.current.value);
      ec = cn.sdo->write(
          object->index, object->subindex,
          std::span<const uint8_t>(bytes.data(), std::min<std::size_t>(cn.current.size, 4)),
          now_ns_);
    } else {
      ec = cn.sdo->read(object->index, object->subindex, now_ns_);
    }
    if (ec) {
      cn.op_active = false;
      sdo_done(cn, ec, {});
    }
  }
}

void ManagingNode::start_object_op(Cn& cn) noexcept {
  const ObjectOp& op = cn.object_ops[cn.object_next];
  cn.op_active = true;
  cn.op_internal = true;
  cn.op_kind = op.kind;
  std::error_code ec;
  if (op.kind == OpKind::kIdentityRead) {
    ec = cn.sdo->read(op.index, op.subindex, now_ns_);
  } else {
    std::span<const uint8_t> value(cn.object_data.data() + op.data_offset, op.data_size);
    if (op.source != ValueSource::kData) {
      const uint32_t v = op.source == ValueSource::kCycleUs    ? config_.cycle_us
                         : op.source == ValueSource::kPreqSize ? cn.st->preq_size
                                                               : cn.st->pres_size;
      store_le32(cn.op_value.data(), v);
      value = std::span<const uint8_t>(cn.op_value.data(), op.data_size);
    }
    ec = cn.sdo->write(op.index, op.subindex, value, now_ns_);
  }
  if (ec) {
    cn.op_active = false;
    sdo_done(cn, ec, {});
  }
}

void ManagingNode::object_done(Cn& cn, std::error_code ec, std::span<const uint8_t> data) noexcept {
  const ObjectOp& op = cn.object_ops[cn.object_next++];
  CnStatus& st = *cn.st;
  if (ec) {
    ++st.object_failures;
    if (st.last_failure_count < st.last_failures.size())
      st.last_failures[st.last_failure_count++] = {op.index, op.subindex,
                                                   op.kind == OpKind::kIdentityRead, ec};
  } else if (op.kind == OpKind::kObjectWrite) {
    ++st.objects_written;
  }
  if (op.kind != OpKind::kIdentityRead) return;
  uint32_t found = 0;
  for (std::size_t i = 0; i < std::min<std::size_t>(data.size(), 4); ++i)
    found |= static_cast<uint32_t>(data[i]) << (8 * i);
  if (!ec && found == op.expected) {
    if (st.identity_mismatch && st.mismatch.index == op.index &&
        st.mismatch.subindex == op.subindex)
      st.identity_mismatch = false;
    return;
  }
  // Not the configured device (or one that cannot say): it is not booted, and is tried again
  // after a reset in case it is replaced.
  st.identity_mismatch = true;
  st.mismatch = {op.index, op.subindex, op.expected, found, static_cast<bool>(ec)};
  reset_node(cn, make_error_code(MnError::kIdentityCheckFailed));
}

void ManagingNode::sdo_done(Cn& cn, std::error_code ec, std::span<const uint8_t> data) noexcept {
  cn.op_active = false;
  cn.sdo_wait_answer = false;
  if (cn.op_internal && cn.op_kind != OpKind::kRegister) {
    if (ec) cn.st->last_error = ec;
    if (ec == SdoError::kConnectionLost) return;  // the node is being reset
    object_done(cn, ec, data);
    if (cn.st->boot == CnBootState::kReset) return;
    start_next_sdo(cn);
    return;
  }
  uint32_t value = 0;
  for (std::size_t i = 0; i < std::min<std::size_t>(data.size(), 4); ++i)
    value |= static_cast<uint32_t>(data[i]) << (8 * i);
  if (ec) {
    ++cn.st->sdo_errors;
    cn.st->last_error = ec;
  }
  if (cn.op_internal) {
    // A setting the bus controller refuses is reported (status) but does not stop the boot.
    ++cn.boot_next;
  } else if (results_count_ < results_.size()) {
    results_[(results_head_ + results_count_++) % results_.size()] = {cn.current.tag, ec, value};
  }
  if (ec == SdoError::kConnectionLost) return;  // the node is being reset
  start_next_sdo(cn);
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
  iso_count_ = 0;
  // SoC MC: toggled when the last cycle of a multiplexed cycle has ended (EPSG DS 301), so a CN
  // can tell where the multiplexed cycle starts.
  if (mux_cycle_len_ > 1 && counters_.cycles > 0 && counters_.cycles % mux_cycle_len_ == 0)
    mc_flag_ = !mc_flag_;
  for (auto& cn : cns_) {
    cn->polled = cn->pres_seen = cn->pres_usable = cn->timed_out = cn->late = false;
    if (!full_cycle() || !cn->st->in_isochronous) continue;
    const uint32_t mux = cn->cfg.multiplex;
    if (mux > 1 && counters_.cycles % mux != cn->cfg.node_id % mux) continue;
    iso_list_[iso_count_++] = cn->cfg.node_id;
  }
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
  return mn_state_ != NmtState::kPreOperational1;
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

uint32_t ManagingNode::pres_timeout_us(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  return cn ? cn->cfg.pres_timeout_us : 0;
}

Result<std::size_t> ManagingNode::build_preq(uint8_t node, std::span<uint8_t> out) noexcept {
  Cn* cn = find(node);
  if (!cn) return MnError::kNodeNotConfigured;
  cn->polled = true;
  PReq preq;
  preq.ready = mn_state_ == NmtState::kOperational;
  preq.multiplexed_slot = cn->cfg.multiplex > 1;
  preq.exception_acknowledge = cn->st->exception_acknowledge;
  preq.payload = std::span<const uint8_t>(cn->preq.data(), cn->st->preq_size);
  return powerlink::build_preq(out, preq_header(config_.mac, cn->st->mac, node), preq);
}

void ManagingNode::on_pres_timeout(uint8_t node) noexcept {
  if (Cn* cn = find(node)) cn->timed_out = true;
}

Result<std::size_t> ManagingNode::build_soa(std::span<uint8_t> out) noexcept {
  // One grant per cycle. Three classes take turns being asked first, so neither a long SDO
  // transfer nor a silent CN starves the others: the MN's own frames, CN invitations, and
  // Ident/StatusRequests.
  const std::size_t n = cns_.size();
  auto pick = [&](int cls) -> bool {
    for (std::size_t k = 0; k < n; ++k) {
      Cn& cn = *cns_[(async_rr_ + k) % n];
      switch (cls) {
        case 0:
          if (cn.outbox_count > 0) {
            soa_service_ = RequestedService::kUnspecifiedInvite;
            soa_target_ = kNodeMn;
            mn_asnd_from_ = &cn;
            return true;
          }
          break;
        case 1:
          if (cn.st->identified && cn.rs > 0 && cn.pr == 7) {
            soa_service_ = RequestedService::kNmtRequestInvite;
          } else if (cn.st->identified && (cn.sdo_wait_answer || cn.rs > 0)) {
            soa_service_ = RequestedService::kUnspecifiedInvite;
          } else {
            break;
          }
          soa_target_ = cn.cfg.node_id;
          return true;
        default:
          if (cn.st->boot == CnBootState::kIdentify) {
            soa_service_ = RequestedService::kIdentRequest;
          } else if (cn.exception_pending && cn.st->boot != CnBootState::kReset) {
            // Exception signalled: fetch its error entries, whatever the boot state.
            soa_service_ = RequestedService::kStatusRequest;
            cn.last_status_request = counters_.cycles;
          } else if (cn.st->boot != CnBootState::kReset &&
                     counters_.cycles - cn.last_status_request >=
                         config_.bus.nmt.status_request_every &&
                     cn.st->boot != CnBootState::kOperational) {
            soa_service_ = RequestedService::kStatusRequest;
            cn.last_status_request = counters_.cycles;
          } else {
            break;
          }
          soa_target_ = cn.cfg.node_id;
          return true;
      }
    }
    return false;
  };
  if (n > 0) {
    const int first = static_cast<int>(counters_.cycles % 3);
    for (int i = 0; i < 3; ++i)
      if (pick((first + i) % 3)) break;
    async_rr_ = (async_rr_ + 1) % n;
  }
  awaiting_asnd_ = soa_service_ != RequestedService::kNone && soa_target_ != kNodeMn;
  SoA soa;
  soa.mn_nmt_state = mn_state_;
  soa.service = soa_service_;
  soa.target = soa_target_;
  if (soa_service_ == RequestedService::kStatusRequest) {
    if (Cn* t = find(soa_target_)) {
      soa.exception_acknowledge = t->st->exception_acknowledge;
      soa.exception_reset = t->exception_reset_due;
      t->exception_reset_due = false;
    }
  }
  return powerlink::build_soa(out, soa_header(config_.mac), soa);
}

Result<std::size_t> ManagingNode::build_mn_asnd(std::span<uint8_t> out) noexcept {
  Cn* cn = mn_asnd_from_;
  if (!cn || cn->outbox_count == 0) return std::size_t{0};
  const std::size_t len = cn->outbox_len[cn->outbox_head];
  if (out.size() < len) return FrameError::kBufferTooSmall;
  std::memcpy(out.data(), cn->outbox[cn->outbox_head].data(), len);
  cn->outbox_head = (cn->outbox_head + 1) % kOutboxDepth;
  --cn->outbox_count;
  if (out[17] == static_cast<uint8_t>(AsndService::kSdo) && cn->sdo->busy())
    cn->sdo_wait_answer = true;
  mn_asnd_from_ = nullptr;
  return len;
}

void ManagingNode::on_async_timeout() noexcept {
  if (awaiting_asnd_) {
    const bool mandatory = soa_service_ == RequestedService::kIdentRequest ||
                           soa_service_ == RequestedService::kStatusRequest;
    ++(mandatory ? counters_.async_timeouts : counters_.async_invites_unused);
  }
  awaiting_asnd_ = false;
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
  return {};
}

void ManagingNode::handle_pres(Cn& cn, const PRes& pres, std::span<const uint8_t>) noexcept {
  cn.pres_seen = true;
  ++cn.st->pres_received;
  cn.rs = pres.request_count;
  cn.pr = pres.priority;
  // EN differing from the EA the MN last sent: the CN has new error entries to fetch.
  cn.st->exception_new = pres.exception_new;
  if (pres.exception_new != cn.st->exception_acknowledge && !cn.exception_pending) {
    cn.exception_pending = true;
    ++cn.st->exceptions_signalled;
  }
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
  // Inputs are usable when the modules' bytes are all there, whatever else the CN appends.
  cn.pres_usable = size >= cn.layout.pres_size;
  reported_state(cn, pres.nmt_state);
}

void ManagingNode::handle_asnd(const FrameHeader& h, const Asnd& asnd) noexcept {
  Cn* cn = find(h.src_node);
  if (!cn) {
    ++counters_.unexpected_frames;
    return;
  }
  if (h.src_node == soa_target_) awaiting_asnd_ = false;
  if (const auto* ident = std::get_if<IdentResponse>(&asnd.body)) {
    cn->rs = ident->request_count;
    cn->pr = ident->priority;
    if (cn->st->boot == CnBootState::kIdentify) {
      const auto& c = cn->cfg;
      if ((c.vendor_id && *c.vendor_id != ident->vendor_id) ||
          (c.product_code && *c.product_code != ident->product_code) ||
          (c.device_type && *c.device_type != ident->device_type) ||
          (c.revision_no && *c.revision_no != ident->revision_no) ||
          (c.serial_no && *c.serial_no != ident->serial_no)) {
        cn->st->last_error = make_error_code(MnError::kIdentMismatch);
        cn->st->nmt = ident->nmt_state;
        return;
      }
      cn->st->identified = true;
      cn->st->mac = h.src_mac;
      cn->st->vendor_id = ident->vendor_id;
      cn->st->product_code = ident->product_code;
      cn->st->preq_size =
          c.preq_size.value_or(ident->poll_out_size ? ident->poll_out_size : cn->layout.preq_size);
      cn->st->pres_size =
          c.pres_size.value_or(ident->poll_in_size ? ident->poll_in_size : cn->layout.pres_size);
      cn->st->preq_size = std::min<uint16_t>(cn->st->preq_size, kMaxIsoPayload);
      std::fill(cn->preq.begin(), cn->preq.end(), 0);
      // Exception signalling starts afresh: ER in the next StatusRequest, EA cleared.
      cn->exception_reset_due = true;
      cn->exception_pending = false;
      cn->st->exception_acknowledge = false;
      enter(*cn, CnBootState::kWaitPreOp2);
    }
    reported_state(*cn, ident->nmt_state);
  } else if (const auto* status = std::get_if<StatusResponse>(&asnd.body)) {
    cn->rs = status->request_count;
    cn->pr = status->priority;
    if (status->entry_count() > 0) {
      cn->st->status_error_entries += static_cast<uint32_t>(status->entry_count());
      cn->st->last_error_code = status->entry(status->entry_count() - 1).code;
    }
    // The entries are read: acknowledge the EN the CN signals (EA follows EN).
    cn->st->exception_new = status->exception_new;
    cn->st->exception_acknowledge = status->exception_new;
    cn->exception_pending = false;
    reported_state(*cn, status->nmt_state);
  } else if (const auto* sdo = std::get_if<Sdo>(&asnd.body)) {
    if (h.dst_node != kNodeMn) return;
    cn->sdo_wait_answer = false;
    cn->sdo->receive(*sdo, now_ns_);
  } else if (const auto* request = std::get_if<NmtRequest>(&asnd.body)) {
    handle_nmt_request(*cn, *request);
  } else {
    // Services this MN does not use (SyncResponse, manufacturer-specific): accepted, and the
    // invitation is not repeated until the CN announces a request again.
    cn->rs = 0;
  }
}

void ManagingNode::handle_nmt_request(Cn& from, const NmtRequest& request) noexcept {
  ++from.st->nmt_requests;
  // The MN alone drives a CN through its boot: a CN may ask to be reset (it is then booted and
  // configured again from the start) but not to be started, stopped or reset elsewhere, which
  // would move the machine behind the MN's back.
  const bool reset = request.command >= static_cast<uint8_t>(NmtCommandId::kResetNode) &&
                     request.command <= static_cast<uint8_t>(NmtCommandId::kSwReset);
  if (!reset || request.target != from.cfg.node_id) {
    ++from.st->nmt_requests_refused;
    from.st->last_error = make_error_code(MnError::kNmtRequestRefused);
    return;
  }
  if (from.st->boot != CnBootState::kReset)
    reset_node(from, make_error_code(MnError::kResetRequested));
}

void ManagingNode::update_mn_state() noexcept {
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
