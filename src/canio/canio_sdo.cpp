// The CAN-I/O driver's register access: configures each module (start-up writes with read-back,
// Rescan), checks the configuration when a node comes back after a silence, and serves the
// daemon's register requests — as a state machine stepped once a cycle by exchange() on the
// cycle thread, the loop that owns the bus (as POWERLINK's SDO is stepped by its cycle). One
// expedited transfer at a time, at most one started a cycle and one per max(period,
// sdo_interval_us): the bus-load budget counts exactly that. All time comes from the driver's
// clock (clock_), so tests drive timeouts, retries and pacing with a fake one. Nothing here
// sleeps, waits, allocates or locks.
#include <algorithm>

#include "canio/canio_bus.hpp"
#include "canio/sdo_expedited.hpp"
#include "core/single_writer.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::canio {
namespace {

constexpr int64_t kMs = 1'000'000;
// A configuration (or check) that failed is tried again this much later.
constexpr int64_t kRetryConfigureNs = 500 * kMs;
// An unconfigurable axis is asked again after 0.5, 1, 2, ... s, at most this.
constexpr int64_t kMaxBackoffNs = 30'000 * kMs;
// Definitive answers (aborts, read-backs that differ) before the axis goes up unverified: a node
// that answers must never keep its axis down; the PosCycle gate then decides whether it delivers.
constexpr unsigned kDefinitiveAttempts = 3;
// A register request for an axis that is being configured waits this long, then is answered
// kNotConfigured.
constexpr int64_t kDeferLimitNs = 2000 * kMs;
// Decisions one step may take without a transfer on the wire (answers from the queue, deferrals):
// bounds the cycle's time in step_sdo().
constexpr int kMaxDecisionsPerStep = 8;

// The Info job's steps: 0 reads EnDatInfoOK, n + 1 channel n's EnDatInfo0N; the next step at or
// after `from` that has a configured channel, kInfoChannels + 1 when none is left.
uint8_t next_info_step(const ModuleSettings& m, uint8_t from) noexcept {
  if (from == 0) return 0;
  for (uint8_t s = from; s <= kInfoChannels; ++s)
    if (m.info_cmd[s - 1] != 0) return s;
  return static_cast<uint8_t>(kInfoChannels + 1);
}
bool has_info(const ModuleSettings& m) noexcept {
  return next_info_step(m, 1) <= kInfoChannels;
}

// CiA 301 aborts that say "this object cannot be read" — the write stands, it just cannot be
// verified: 0x06010000 unsupported access, 0x06010001 attempt to read a write-only object.
[[nodiscard]] bool cannot_be_read(std::error_code ec) noexcept {
  const auto code = sdo_abort_code(ec);
  return code == sdo_abort::kUnsupportedAccess || code == sdo_abort::kWriteOnly;
}

// No answer at all: says nothing about the module (retried).
[[nodiscard]] bool transient(std::error_code ec) noexcept {
  return ec == CanioBusError::kSdoTimeout || ec == CanioBusError::kSdoSendFailed;
}

[[nodiscard]] std::string register_name(uint16_t reg) {
  const RegisterInfo* info = find_register(reg);
  return std::to_string(reg) + " (" + std::string(info ? info->name : "?") + ")";
}

// The registers read after a silence: three tell a module that kept its configuration from one
// that was power cycled (EnDat disabled, MTUs unset); each configured additional-information
// channel's EnDatInfoCmd0n is read back as well, like every register the configuration wrote
// and the cycle depends on.
struct ConfigurationChecks {
  std::array<RegisterWrite, 3 + std::tuple_size_v<decltype(ModuleSettings::info_cmd)>> checks{};
  std::size_t count = 0;
  [[nodiscard]] const RegisterWrite& operator[](std::size_t i) const noexcept { return checks[i]; }
};
[[nodiscard]] ConfigurationChecks configuration_checks(const ModuleSettings& m) noexcept {
  ConfigurationChecks c;
  c.checks[c.count++] = {reg::kEnDatMode, 1, m.endat_mode()};
  c.checks[c.count++] = {reg::kOutputMtu, 1, m.output_mtu};
  c.checks[c.count++] = {reg::kInputMtu, 1, m.input_mtu};
  const InfoCommandWrites info = info_command_writes(m);
  for (const RegisterWrite& w : info.span()) c.checks[c.count++] = w;
  return c;
}

}  // namespace

// ---- Last error (status) -----------------------------------------------------------------------

void CanioBus::NoteCell::store(const SdoNote& n) noexcept {
  // Sequence counter: odd while the fields change. Release stores, so that a reader that sees a
  // field of this note also sees the odd counter before it.
  const uint32_t s = seq_.load(std::memory_order_relaxed);
  seq_.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  kind_.store(static_cast<uint8_t>(n.kind), std::memory_order_release);
  unverified_after_.store(n.unverified_after, std::memory_order_release);
  reg_.store(n.reg, std::memory_order_release);
  value_.store(n.value, std::memory_order_release);
  code_.store(n.error.value(), std::memory_order_release);
  category_.store(n.error ? &n.error.category() : nullptr, std::memory_order_release);
  seq_.store(s + 2, std::memory_order_release);
}

CanioBus::SdoNote CanioBus::NoteCell::load() const noexcept {
  for (;;) {
    const uint32_t before = seq_.load(std::memory_order_acquire);
    SdoNote n;
    n.kind = static_cast<NoteKind>(kind_.load(std::memory_order_acquire));
    n.unverified_after = unverified_after_.load(std::memory_order_acquire);
    n.reg = reg_.load(std::memory_order_acquire);
    n.value = value_.load(std::memory_order_acquire);
    const int code = code_.load(std::memory_order_acquire);
    const std::error_category* category = category_.load(std::memory_order_acquire);
    if (category) n.error = std::error_code(code, *category);
    if ((before & 1U) == 0 && seq_.load(std::memory_order_acquire) == before) return n;
  }
}

std::string CanioBus::axis_reason(std::size_t axis) const {
  if (axis >= options_.axes.size()) return {};
  const CanioAxisState st = axis_counters_[axis].state.load(std::memory_order_relaxed);
  if (st == CanioAxisState::IdentityMismatch)
    return describe_identity(node_identity(axis_node_[axis])) +
           "; the node is not started (topology.on_mismatch: refuse), checked again with "
           "back-off (up to 30 s) and after its next boot-up";
  if (st != CanioAxisState::Unconfigurable) return std::string(reason(st));
  const SdoNote n = notes_[axis].load();
  // "unconfigurable: <register> <abort text>"
  return "unconfigurable: " + register_name(n.reg) + " " + n.error.message() +
         "; retried with back-off (up to 30 s)";
}

std::string CanioBus::axis_last_error(std::size_t axis) const {
  if (axis >= options_.axes.size()) return {};
  const SdoNote n = notes_[axis].load();
  const std::string why = n.error.message();
  std::string text;
  switch (n.kind) {
    case NoteKind::None:
      return {};
    case NoteKind::Configuring:
      text = "configuring the module: register " + register_name(n.reg) + " = " +
             std::to_string(n.value) + ": " + why;
      break;
    case NoteKind::Rescan:
      text = "Rescan (EnDatAck bit 1): " + why;
      break;
    case NoteKind::Checking:
      text =
          "checking the configuration after silence: register " + register_name(n.reg) + ": " + why;
      break;
    case NoteKind::Refused:
      text =
          "register " + register_name(n.reg) + " = " + std::to_string(n.value) + " refused: " + why;
      break;
    case NoteKind::Heartbeat:
      text = "heartbeat producer time 0x1017 = " + std::to_string(n.value) + " ms: " + why +
             " (no heartbeat watched)";
      break;
  }
  if (n.unverified_after > 0)
    text = "configured UNVERIFIED after " + std::to_string(n.unverified_after) +
           " definitive answers: " + text;
  return text;
}

// ---- The state machine (cycle thread) -----------------------------------------------------------

void CanioBus::step_sdo(int64_t now) noexcept {
  // The answer to the transfer in flight (and boot-up, heartbeat, EMCY); anything else on the
  // SDO port (a late answer to a transfer that timed out) is dropped here, before the next
  // request goes out.
  drain_node_port(now);
  if (auto o = sdo_client_.tick(now))
    transfer_done(now, make_error_code(CanioBusError::kSdoTimeout), 0, 0);

  for (int d = 0; d < kMaxDecisionsPerStep && !sdo_client_.busy(); ++d) {
    if (!registers().flush()) return;  // a result waits: the normal thread polls it later
    if (job_.kind == SdoJobKind::None && !next_job(now)) return;
    if (job_.kind == SdoJobKind::None) continue;  // answered without a transfer
    // The job's next transfer, paced: at most one a step and one per max(period,
    // sdo_interval_us). A transfer that cannot start (no SDO object) ends at once.
    if (now < next_sdo_ns_) return;
    if (issue(now)) return;
  }
}

bool CanioBus::next_job(int64_t now) noexcept {
  const std::size_t n = options_.axes.size();
  // A request that waited too long for its axis' configuration.
  for (std::size_t k = 0; k < deferred_count_; ++k) {
    const Deferred& d = deferred_[k];
    if (!axis_sdo_[d.request.axis].reconfigure || now - d.since_ns <= kDeferLimitNs) continue;
    const RegisterRequest r = d.request;
    std::move(deferred_.begin() + static_cast<std::ptrdiff_t>(k) + 1,
              deferred_.begin() + static_cast<std::ptrdiff_t>(deferred_count_),
              deferred_.begin() + static_cast<std::ptrdiff_t>(k));
    --deferred_count_;
    answer(r, make_error_code(CanioBusError::kNotConfigured), 0);
    return true;
  }
  // A module to configure (or to check after a silence), round robin over the axes.
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = (next_axis_ + k) % n;
    AxisSdo& a = axis_sdo_[i];
    if (!a.reconfigure || now < a.retry_at_ns) continue;
    next_axis_ = (i + 1) % n;
    // Who is there first: a node whose identity is due is read before any of its modules is
    // configured or checked (canio_identity.cpp).
    if (nodes_[axis_node_[i]].identity_due && start_identity(i)) return true;
    // Back after silence: a module that kept its configuration (the node was only late or
    // disconnected) needs three reads; one that was power-cycled is configured anew. With
    // verify none nothing is read: the module is configured again.
    if (axis_counters_[i].configurations.load(std::memory_order_relaxed) > 0 &&
        options_.bus.verify != CanVerify::None && !a.fresh) {
      job_ = SdoJob{};
      job_.kind = SdoJobKind::Check;
      job_.stage = SdoStage::Read;
      job_.axis = static_cast<uint16_t>(i);
    } else {
      start_configure(i);
    }
    return true;
  }
  // A request that waited for its axis, which is configured now (oldest first).
  for (std::size_t k = 0; k < deferred_count_; ++k) {
    if (axis_sdo_[deferred_[k].request.axis].reconfigure) continue;
    const RegisterRequest r = deferred_[k].request;
    std::move(deferred_.begin() + static_cast<std::ptrdiff_t>(k) + 1,
              deferred_.begin() + static_cast<std::ptrdiff_t>(deferred_count_),
              deferred_.begin() + static_cast<std::ptrdiff_t>(k));
    --deferred_count_;
    start_request(r);
    return true;
  }
  // The additional-information channels of a configured axis, when due (one axis a job).
  for (std::size_t i = 0; i < n; ++i) {
    AxisSdo& a = axis_sdo_[i];
    if (a.reconfigure || now < a.info_due_ns || !has_info(options_.axes[i].module)) continue;
    a.info_due_ns = now + int64_t{options_.bus.info_interval_ms} * kMs;
    job_ = SdoJob{};
    job_.kind = SdoJobKind::Info;
    job_.stage = SdoStage::Read;
    job_.axis = static_cast<uint16_t>(i);
    return true;
  }
  // The daemon's next request. One for an axis being configured waits (its identification needs
  // the Rescan first); while the waiting room is full it stays queued.
  offer_now_ = now;
  return registers().serve(*this, 1) == 1;
}

RegisterTarget::Offer CanioBus::offer(const RegisterRequest& request) noexcept {
  if (request.axis >= options_.axes.size()) {
    answer(request, make_error_code(CanioBusError::kNoSuchAxis), 0);
    return Offer::kTaken;
  }
  if (axis_sdo_[request.axis].reconfigure) {
    if (deferred_count_ == deferred_.size()) return Offer::kWait;
    deferred_[deferred_count_++] = {request, offer_now_};
    return Offer::kTaken;
  }
  start_request(request);
  return Offer::kTaken;
}

void CanioBus::start_configure(std::size_t axis) noexcept {
  job_ = SdoJob{};
  job_.kind = SdoJobKind::Configure;
  job_.stage = SdoStage::Write;
  job_.axis = static_cast<uint16_t>(axis);
  const ModuleSettings& module = options_.axes[axis].module;
  const auto startup = startup_writes(module);
  std::copy(startup.begin(), startup.end(), job_.writes.begin());
  job_.write_count = static_cast<uint8_t>(startup.size());
  // The additional-information channels after the start-up configuration (as the POWERLINK MN
  // writes them): a refusal is reported like any register's but EnDatMode's.
  const InfoCommandWrites info = info_command_writes(module);
  for (const RegisterWrite& w : info.span()) job_.writes[job_.write_count++] = w;
}

uint16_t CanioBus::info_step_reg(uint8_t step) noexcept {
  if (step == 0) return reg::kEnDatInfoOk;
  constexpr const RegisterInfo& r = od_entry("EnDatInfo01..04");
  return static_cast<uint16_t>(r.number + (step - 1) * r.stride);
}

void CanioBus::info_step_done(std::error_code ec, uint32_t value) noexcept {
  const std::size_t axis = job_.axis;
  if (ec) {
    // This round is lost: the last values stay (their age grows); the next round is due as
    // planned.
    single_writer_add(axis_counters_[axis].sdo_errors);
    job_.kind = SdoJobKind::None;
    return;
  }
  if (job_.step == 0) {
    job_.info_ok = static_cast<uint8_t>(value);
  } else {
    job_.info[job_.step - 1] = static_cast<uint16_t>(value);
  }
  job_.step = next_info_step(options_.axes[axis].module, static_cast<uint8_t>(job_.step + 1));
  if (job_.step <= kInfoChannels) return;
  AxisSdo& a = axis_sdo_[axis];
  a.info_ok = job_.info_ok;
  a.info = job_.info;
  a.info_ready = true;
  job_.kind = SdoJobKind::None;
}

void CanioBus::start_request(const RegisterRequest& request) noexcept {
  job_ = SdoJob{};
  job_.kind = SdoJobKind::Request;
  job_.axis = request.axis;
  job_.request = request;
  if (request.write) {
    const RegisterInfo* info = find_register(request.reg);
    // Self-clearing command registers (EnDatAck) read back 0: not verified.
    job_.verify = !(info && info->direction == RegisterDirection::Command) &&
                  options_.bus.verify != CanVerify::None;
    job_.stage = SdoStage::Write;
  } else {
    job_.stage = SdoStage::Read;
  }
}

CanioBus::SdoOp CanioBus::current_op() const noexcept {
  switch (job_.kind) {
    case SdoJobKind::Configure: {
      if (job_.stage == SdoStage::Rescan) return {reg::kEnDatAck, 1, true, 0x02};
      if (job_.stage == SdoStage::Heartbeat)
        return {0, 2, true, nodes_[axis_node_[job_.axis]].heartbeat_ms, kHeartbeatProducerIndex, 0};
      const RegisterWrite& w = job_.writes[job_.step];
      return {w.reg, w.size, job_.stage == SdoStage::Write, w.value};
    }
    case SdoJobKind::Info:
      return {info_step_reg(job_.step), static_cast<uint8_t>(job_.step == 0 ? 1 : 2), false, 0};
    case SdoJobKind::Check: {
      const RegisterWrite c = configuration_checks(options_.axes[job_.axis].module)[job_.step];
      return {c.reg, c.size, false, 0};
    }
    case SdoJobKind::Request:
      return {job_.request.reg, job_.request.size, job_.stage == SdoStage::Write,
              job_.request.value};
    case SdoJobKind::Identity: {
      const IdentityField& f = kIdentityFields[job_.step];
      return {0, 4, false, 0, f.index, f.subindex};
    }
    case SdoJobKind::None:
      break;
  }
  return {};
}

bool CanioBus::issue(int64_t now) noexcept {
  const SdoOp op = current_op();
  const CanioAxisPlan& a = options_.axes[job_.axis];
  if (!sdo_port_) {
    transfer_done(now, make_error_code(CanioBusError::kNoAcyclicTransport), 0, 0);
    return false;
  }
  auto obj = sdo_mapping_.object_for(a.slot, op.reg);
  if (op.index != 0) obj = SdoObject{op.index, op.subindex};
  if (!obj) {
    transfer_done(now, make_error_code(CanioBusError::kNoSdoObject), 0, 0);
    return false;
  }
  single_writer_add(axis_counters_[job_.axis].sdo_transfers);
  // The pacing counts every transfer started; a late step does not earn a burst (at most one
  // period of slack is kept).
  const int64_t interval =
      int64_t{std::max(options_.period_us, options_.bus.sdo_interval_us)} * 1000;
  next_sdo_ns_ = std::max(next_sdo_ns_, now - int64_t{options_.period_us} * 1000) +
                 std::max<int64_t>(interval, 1);
  auto frame = op.write
                   ? sdo_client_.write(a.node, obj->index, obj->subindex, op.size, op.value, now)
                   : sdo_client_.read(a.node, obj->index, obj->subindex, op.size, now);
  if (!frame) {
    transfer_done(now, frame.error(), 0, 0);
    return true;
  }
  if (!sdo_port_->send(*frame).sent()) {
    sdo_client_.cancel();
    transfer_done(now, make_error_code(CanioBusError::kSdoSendFailed), 0, 0);
  }
  return true;
}

void CanioBus::transfer_done(int64_t now, std::error_code ec, uint32_t value,
                             uint8_t size) noexcept {
  switch (job_.kind) {
    case SdoJobKind::Configure:
      configure_step_done(now, ec, value);
      return;
    case SdoJobKind::Check:
      check_step_done(now, ec, value, size);
      return;
    case SdoJobKind::Request:
      request_step_done(ec, value);
      return;
    case SdoJobKind::Identity:
      identity_step_done(now, ec, value);
      return;
    case SdoJobKind::Info:
      info_step_done(ec, value);
      return;
    case SdoJobKind::None:
      return;
  }
}

void CanioBus::configure_step_done(int64_t now, std::error_code ec, uint32_t value) noexcept {
  const std::size_t axis = job_.axis;
  if (job_.stage == SdoStage::Rescan) {
    // Datasheet §11.6.2.3: EnDatAck bit 1 (Rescan) makes the module read the encoder's
    // identification again. The module boots with EnDat disabled under function model 254, so
    // the identification is read only now; the daemon's identification reads (requests held
    // while the axis is configuring) follow.
    if (ec) {
      note(axis, {NoteKind::Rescan, 0, reg::kEnDatAck, 0x02, ec});
      if (transient(ec)) {
        finish_configure(now, ec, false);
        return;
      }
      // Refused: without a Rescan the module never reads its encoder.
      unconfigurable(now, reg::kEnDatAck, 0x02, ec);
      return;
    }
    single_writer_add(axis_counters_[axis].rescans);
    finish_configure(now, job_.mismatch, true);
    return;
  }
  if (job_.stage == SdoStage::Heartbeat) {
    // The node's heartbeat producer time (0x1017): refused, the node is not watched by heartbeat
    // (last_error says so); the axis does not depend on it.
    const std::size_t k = axis_node_[axis];
    node_counters_[k].heartbeat_watched.store(!ec, std::memory_order_relaxed);
    if (ec && transient(ec)) {
      note(axis, {NoteKind::Heartbeat, 0, 0, nodes_[k].heartbeat_ms, ec});
      finish_configure(now, ec, false);
      return;
    }
    if (ec) {
      single_writer_add(axis_counters_[axis].write_aborts);
      if (!job_.refused) {
        job_.refused = ec;
        job_.refused_reg = 0;
        job_.refused_value = nodes_[k].heartbeat_ms;
      }
    }
    job_.heartbeat_done = true;
    after_writes(now);
    return;
  }
  const RegisterWrite& w = job_.writes[job_.step];
  if (job_.stage == SdoStage::Write) {
    if (ec && transient(ec)) {
      // No answer says nothing about the module: the attempt is repeated later.
      note(axis, {NoteKind::Configuring, 0, w.reg, w.value, ec});
      finish_configure(now, ec, false);
      return;
    }
    if (ec) {
      // Refused (an abort, or an answer that is not an acknowledgement). EnDatMode is what the
      // axis needs: without it the module never acquires a position — unconfigurable, retried
      // with back-off. Any other register (prescaler, SinCos window, MTUs, ...) does not change
      // whether positions arrive: the remaining registers, EnDatMode among them, are written
      // all the same and the refusal is reported.
      single_writer_add(axis_counters_[axis].write_aborts);
      if (w.reg == reg::kEnDatMode) {
        unconfigurable(now, w.reg, w.value, ec);
        return;
      }
      if (!job_.refused) {
        job_.refused = ec;
        job_.refused_reg = w.reg;
        job_.refused_value = w.value;
      }
    } else if (options_.bus.verify != CanVerify::None) {
      job_.stage = SdoStage::ReadBack;
      return;
    }
  } else {  // ReadBack
    std::error_code differs;
    if (ec && transient(ec)) {
      note(axis, {NoteKind::Configuring, 0, w.reg, w.value, ec});
      finish_configure(now, ec, false);
      return;
    }
    if (cannot_be_read(ec) || (ec && sdo_abort_code(ec))) {
      // The write was acknowledged; a read that is refused (write-only, unsupported access, or
      // any other abort — "object does not exist" from a controller that maps writes only)
      // cannot prove it: the write stays unverified, not failed.
      single_writer_add(axis_counters_[axis].unverified);
    } else if (ec == SdoFrameError::kSizeMismatch) {
      differs = make_error_code(CanioBusError::kReadBackSize);
    } else if (ec) {
      differs = ec;  // an answer that is not this read's: definitive, the attempt is repeated
    } else if (value != w.value) {
      differs = make_error_code(CanioBusError::kReadBackMismatch);
    }
    // A read-back that differs does not stop the configuration: the write was acknowledged, the
    // remaining registers (EnDatMode last) are written all the same, and the attempt counts as a
    // definitive answer at the end.
    if (differs && !job_.mismatch) {
      job_.mismatch = differs;
      job_.mismatch_reg = w.reg;
      job_.mismatch_value = w.value;
    }
  }
  job_.stage = SdoStage::Write;
  if (++job_.step < job_.write_count) return;
  after_writes(now);
}

void CanioBus::after_writes(int64_t now) noexcept {
  const std::size_t axis = job_.axis;
  const std::size_t k = axis_node_[axis];
  // The heartbeat producer time is the node's: written with its first axis.
  const bool first_of_node =
      std::find(axis_node_.begin(), axis_node_.end(), static_cast<uint16_t>(k)) ==
      axis_node_.begin() + static_cast<std::ptrdiff_t>(axis);
  if (!job_.heartbeat_done && nodes_[k].heartbeat_ms != 0 && first_of_node) {
    job_.stage = SdoStage::Heartbeat;
    return;
  }
  if (options_.axes[axis].module.endat_enable) {
    job_.stage = SdoStage::Rescan;
    return;
  }
  finish_configure(now, job_.mismatch, true);
}

void CanioBus::unconfigurable(int64_t now, uint16_t reg, uint32_t value,
                              std::error_code ec) noexcept {
  const std::size_t axis = job_.axis;
  AxisSdo& a = axis_sdo_[axis];
  note(axis, {NoteKind::Refused, 0, reg, value, ec});
  axis_counters_[axis].unconfigurable.store(true, std::memory_order_relaxed);
  single_writer_add(axis_counters_[axis].sdo_errors);
  job_.kind = SdoJobKind::None;
  // Bounded back-off: the refusal may be the node's state (it may need a restart, or a tool
  // holds it); asking every 500 ms for ever would load the bus for nothing.
  a.backoff_ns = a.backoff_ns == 0 ? kRetryConfigureNs : std::min(2 * a.backoff_ns, kMaxBackoffNs);
  a.retry_at_ns = now + a.backoff_ns;
}

void CanioBus::finish_configure(int64_t now, std::error_code ec, bool completed) noexcept {
  const std::size_t axis = job_.axis;
  AxisSdo& a = axis_sdo_[axis];
  // Completed: every register written, `ec` the first read-back that differed (or none); the
  // note says so. Else the note already names the transfer that stopped it.
  const bool mismatch = completed && ec;
  if (completed) {
    if (job_.refused)
      note(axis, {job_.refused_reg == 0 ? NoteKind::Heartbeat : NoteKind::Refused, 0,
                  job_.refused_reg, job_.refused_value, job_.refused});
    else if (mismatch)
      note(axis, {NoteKind::Configuring, 0, job_.mismatch_reg, job_.mismatch_value, job_.mismatch});
    else
      note(axis, SdoNote{});
  }
  job_.kind = SdoJobKind::None;
  if (!ec) {
    single_writer_add(axis_counters_[axis].configurations);
    if (job_.refused) single_writer_add(axis_counters_[axis].sdo_errors);
    mark_configured(axis, now);
    return;
  }
  single_writer_add(axis_counters_[axis].sdo_errors);
  a.retry_at_ns = now + kRetryConfigureNs;
  // The node answers, but not as written (another value or size): after a few attempts the axis
  // goes up with the configuration unverified (last_error says why); the PosCycle gate keeps it
  // Stale unless the module really delivers positions.
  if (!transient(ec) && ++a.definitive >= kDefinitiveAttempts) {
    SdoNote n = notes_[axis].load();
    n.unverified_after = static_cast<uint8_t>(std::min(a.definitive, 255U));
    note(axis, n);
    single_writer_add(axis_counters_[axis].configurations);
    mark_configured(axis, now);
  }
}

void CanioBus::check_step_done(int64_t now, std::error_code ec, uint32_t value,
                               uint8_t size) noexcept {
  const std::size_t axis = job_.axis;
  const RegisterWrite c = configuration_checks(options_.axes[axis].module)[job_.step];
  if (ec && transient(ec)) {
    // No answer proves nothing about the configuration: asked again later; this axis publishes
    // nothing meanwhile.
    note(axis, {NoteKind::Checking, 0, c.reg, 0, ec});
    single_writer_add(axis_counters_[axis].sdo_errors);
    axis_sdo_[axis].retry_at_ns = now + kRetryConfigureNs;
    job_.kind = SdoJobKind::None;
    return;
  }
  // Any answer that is not this value of this size — another value, another size, an abort
  // (also "cannot be read": then nothing can be proven) — configures the module again.
  if (ec || size != c.size || value != c.value) {
    start_configure(axis);
    return;
  }
  if (++job_.step < configuration_checks(options_.axes[axis].module).count) return;
  note(axis, {});
  job_.kind = SdoJobKind::None;
  mark_configured(axis, now);
}

void CanioBus::request_step_done(std::error_code ec, uint32_t value) noexcept {
  const RegisterRequest& r = job_.request;
  if (job_.stage == SdoStage::Write && !ec && job_.verify) {
    job_.stage = SdoStage::ReadBack;
    return;
  }
  if (job_.stage == SdoStage::ReadBack) {
    if (cannot_be_read(ec)) {
      single_writer_add(axis_counters_[r.axis].unverified);
      ec = {};
    } else if (ec == SdoFrameError::kSizeMismatch) {
      ec = make_error_code(CanioBusError::kReadBackSize);
    } else if (!ec && value != r.value) {
      ec = make_error_code(CanioBusError::kReadBackMismatch);
    }
    value = 0;
  } else if (job_.stage == SdoStage::Write) {
    value = 0;
  }
  job_.kind = SdoJobKind::None;
  answer(r, ec, value);
}

void CanioBus::mark_configured(std::size_t axis, int64_t now) noexcept {
  AxisSdo& a = axis_sdo_[axis];
  a.definitive = 0;
  a.reconfigure = false;
  a.fresh = false;
  a.backoff_ns = 0;
  axis_counters_[axis].unconfigurable.store(false, std::memory_order_relaxed);
  // The configuration is the proof: the first samples after it (the node was silent while
  // pre-operational) are not a return from silence that needs checking again.
  axis_counters_[axis].last_sample_ns.store(0, std::memory_order_relaxed);
  single_writer_add(axis_counters_[axis].generation);
  axis_counters_[axis].configured.store(true, std::memory_order_release);
  node_configured(axis, now);
}

void CanioBus::answer(const RegisterRequest& request, std::error_code ec, uint32_t value) noexcept {
  RegisterResult res;
  res.tag = request.tag;
  res.error = ec;
  res.value = value;
  if (ec && request.axis < options_.axes.size() && ec != CanioBusError::kNotConfigured)
    single_writer_add(axis_counters_[request.axis].sdo_errors);
  // The normal thread has not polled for a while: the path holds it until the queue has room and
  // step_sdo() starts no other job meanwhile (so it is the only one held).
  (void)registers().complete(res);
}

}  // namespace ds1928::canio
