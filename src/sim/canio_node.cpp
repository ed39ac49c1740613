#include "sim/canio_node.hpp"

#include <algorithm>
#include <array>
#include <limits>

#include "canio/canopen_nmt.hpp"
#include "canio/object_codec.hpp"
#include "canio/sdo_expedited.hpp"
#include "core/clock.hpp"
#include "core/sdo_abort.hpp"
#include "sim/sim_error.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::sim {

CanioNodeConfig canio_node_from_config(const CanioBusConfig& canio,
                                       std::span<const AxisConfig> axes,
                                       const SimulatedBusConfig& simulated, uint8_t node) {
  CanioNodeConfig n;
  n.node = node;
  n.little_endian = canio.little_endian;
  n.sync_enabled = canio.sync_enabled;
  n.sync_id = canio.sync_id;
  n.sdo_overrides = canio.sdo_overrides;
  // The identity canio.nodes[] expects, where it says one: the simulator is the planned node.
  for (const CanioNodeOptions& o : canio.nodes) {
    if (o.node != node) continue;
    if (o.identity.device_type) n.identity.device_type = *o.identity.device_type;
    if (o.identity.vendor_id) n.identity.vendor_id = *o.identity.vendor_id;
    if (o.identity.product_code) n.identity.product_code = *o.identity.product_code;
    if (o.identity.revision_no) n.identity.revision_no = *o.identity.revision_no;
    if (o.identity.serial_no) n.identity.serial_no = *o.identity.serial_no;
  }
  for (std::size_t i = 0; i < axes.size(); ++i) {
    const AxisConfig& a = axes[i];
    if (a.node != node) continue;
    CanioNodeModule m;
    m.slot = a.slot;
    m.ids = canio_axis_ids(canio, a, i);
    if (i < simulated.axes.size()) m.sim = simulated.axes[i];
    n.modules.push_back(m);
  }
  return n;
}

CanioNode::CanioNode(CanioNodeConfig config, canio::CanPort& port)
    : config_(std::move(config)),
      port_(port),
      mapping_(config_.sdo_overrides),
      rng_(config_.faults.seed),
      heartbeat_ms_(config_.heartbeat_ms) {
  for (const CanioNodeModule& m : config_.modules) {
    // An encoder file that does not load was refused by the configuration already.
    auto encoder = load_encoder(m.sim);
    modules_.push_back(std::make_unique<Ds1928Module>(
        FunctionModel::BusController, m.sim,
        encoder.description ? std::move(*encoder.description) : default_encoder_description()));
  }
  last_inputs_.resize(modules_.size());
  have_last_.assign(modules_.size(), false);
}

CanioNode::~CanioNode() = default;

std::error_code CanioNode::open() {
  std::vector<canio::CanIdFilter> ids;
  if (config_.sync_enabled) ids.push_back({config_.sync_id, false});
  for (const CanioNodeModule& m : config_.modules) ids.push_back({m.ids.output, false});
  ids.push_back({canio::kSdoRequestBase + config_.node, false});
  ids.push_back({canio::kNmtCobId, false});
  if (auto ec = port_.set_filters(ids)) return ec;
  boot();  // the modules are in their power-up state
  return {};
}

void CanioNode::power_up() {
  for (auto& m : modules_) m->power_up();
  have_last_.assign(modules_.size(), false);
  heartbeat_ms_ = config_.heartbeat_ms;
  // A reset drops what the controller had queued.
  tx_head_ = 0;
  tx_count_ = 0;
  boot();
}

void CanioNode::boot() {
  ++counters_.boot_ups;
  nmt_.store(canio::NmtState::PreOperational);
  if (auto f = canio::build_error_control(config_.node, canio::NmtState::BootUp))
    if (!silent_) send(*f);
  next_heartbeat_ns_ = now() + int64_t{heartbeat_ms_} * 1'000'000;
  if (config_.self_start) nmt_.store(canio::NmtState::Operational);
}

void CanioNode::request_emcy(uint16_t error_code, uint8_t error_register,
                             std::array<uint8_t, 5> vendor) noexcept {
  uint64_t w = uint64_t{error_code} | (uint64_t{error_register} << 16);
  for (std::size_t k = 0; k < vendor.size(); ++k) w |= uint64_t{vendor[k]} << (24 + 8 * k);
  emcy_word_.store(w);
  emcy_requested_.store(true);
}

void CanioNode::on_nmt(const canio::NmtMessage& m) {
  using canio::NmtCommand;
  using canio::NmtState;
  if (!canio::addresses(m, config_.node)) return;
  ++counters_.nmt_commands;
  switch (m.command) {
    case NmtCommand::Start:
      if (starts_ignored_ < config_.faults.ignore_nmt_starts) {
        ++starts_ignored_;
        return;
      }
      nmt_.store(NmtState::Operational);
      return;
    case NmtCommand::Stop:
      nmt_.store(NmtState::Stopped);
      tx_count_ = 0;  // a stopped node sends no process data, queued or not
      return;
    case NmtCommand::EnterPreOperational:
      nmt_.store(NmtState::PreOperational);
      tx_count_ = 0;
      return;
    case NmtCommand::ResetNode:
      power_up();  // application and communication parameters back to their power-up values
      return;
    case NmtCommand::ResetCommunication:
      // Communication parameters only (the heartbeat time among them); the modules keep theirs.
      heartbeat_ms_ = config_.heartbeat_ms;
      tx_head_ = 0;
      tx_count_ = 0;
      boot();
      return;
  }
}

void CanioNode::service_faults() {
  if (reset_requested_.exchange(false)) power_up();
  if (emcy_requested_.exchange(false)) {
    const uint64_t w = emcy_word_.load();
    canio::Emcy e;
    e.node = config_.node;
    e.error_code = static_cast<uint16_t>(w & 0xFFFF);
    e.error_register = static_cast<uint8_t>((w >> 16) & 0xFF);
    for (std::size_t k = 0; k < e.vendor.size(); ++k)
      e.vendor[k] = static_cast<uint8_t>((w >> (24 + 8 * k)) & 0xFF);
    // EMCY is produced in pre-operational and operational, not when stopped (CiA 301).
    if (nmt_.load() != canio::NmtState::Stopped)
      if (auto f = canio::build_emcy(e)) {
        ++counters_.emcys;
        if (!silent_) send(*f);
      }
  }
}

void CanioNode::send(const canio::CanFrame& f) {
  if (!port_.send(f).sent()) ++counters_.send_failures;
}

int64_t CanioNode::now() const {
  return config_.clock ? config_.clock() : rt::now_ns();
}

void CanioNode::queue(const canio::CanFrame& f, int64_t due_ns) {
  if (tx_count_ == tx_.size()) {
    ++counters_.send_failures;  // the controller's TX buffer is full
    return;
  }
  // In order: a frame is never sent before one queued earlier (FIFO transmitter); a late object
  // 2 therefore holds back the answers to the next SYNC until it has gone (docs/canio.md, W2).
  if (tx_count_ > 0) {
    const Queued& last = tx_[(tx_head_ + tx_count_ - 1) % tx_.size()];
    due_ns = std::max(due_ns, last.due_ns);
  }
  tx_[(tx_head_ + tx_count_) % tx_.size()] = {f, due_ns};
  ++tx_count_;
}

int64_t CanioNode::next_due_ns() const noexcept {
  const int64_t hb = heartbeat_ms_ != 0 ? next_heartbeat_ns_ : std::numeric_limits<int64_t>::max();
  return std::min(tx_count_ == 0 ? std::numeric_limits<int64_t>::max() : tx_[tx_head_].due_ns, hb);
}

void CanioNode::send_due() {
  const int64_t t = now();
  if (heartbeat_ms_ != 0 && t >= next_heartbeat_ns_) {
    // Heartbeat producer (CiA 301 §7.2.8.3.2.2): the NMT state every producer time.
    if (auto f = canio::build_error_control(config_.node, nmt_.load())) {
      ++counters_.heartbeats;
      if (!silent_) send(*f);
    }
    const int64_t period = int64_t{heartbeat_ms_} * 1'000'000;
    next_heartbeat_ns_ = std::max(next_heartbeat_ns_ + period, t + 1);
  }
  while (tx_count_ > 0 && tx_[tx_head_].due_ns <= t) {
    if (!silent_) send(tx_[tx_head_].frame);
    tx_head_ = (tx_head_ + 1) % tx_.size();
    --tx_count_;
  }
}

void CanioNode::answer(std::size_t i, int64_t time_ns) {
  Ds1928Module& m = *modules_[i];
  ModuleInputs in;
  if (stalled_ && have_last_[i]) {
    // The acquisition stalled: the module keeps answering SYNC with its last position and
    // PosCycle (datasheet §11.5.5: PosCycle counts new positions only).
    in = last_inputs_[i];
    ++counters_.stalled_answers;
  } else {
    m.tick(time_ns, static_cast<uint64_t>(time_ns / 1000));
    in = m.inputs();
    last_inputs_[i] = in;
    have_last_[i] = true;
  }
  if (on_inputs) on_inputs(i, time_ns, in);
  if (on_answer) on_answer(counters_.syncs, i, in);
  const CanioNodeModule& cfg = config_.modules[i];
  canio::CanObject pos{};
  canio::CanObject status{};
  canio::pack_position_object(
      in, config_.little_endian ? canio::ByteOrder::Little : canio::ByteOrder::Big, pos);
  canio::pack_status_object(in, status);
  std::bernoulli_distribution drop(config_.faults.drop);
  std::bernoulli_distribution late(config_.faults.late_object2);
  const int64_t due = time_ns + config_.sync_reaction_ns;
  for (int k = 0; k < 2; ++k) {
    canio::CanFrame f = canio::make_standard_frame(cfg.ids.input[k], k == 0 ? pos : status);
    if (k == 0 && config_.faults.wrong_length_every != 0 &&
        ++position_objects_ % config_.faults.wrong_length_every == 0)
      f.dlc = 7;
    if (config_.faults.drop > 0 && drop(rng_)) {
      ++counters_.inputs_dropped;
      continue;
    }
    int64_t at = due;
    if (k == 1 && config_.faults.late_object2 > 0 && late(rng_)) {
      at += config_.faults.late_object2_ns;
      ++counters_.inputs_late;
    }
    queue(f, at);
    ++counters_.inputs_sent;
  }
}

void CanioNode::serve_sdo(const canio::CanFrame& f) {
  using canio::SdoCommand;
  ++counters_.sdo_requests;
  auto request = canio::parse_sdo(config_.node, false, f);
  if (!request) return;  // not an expedited request: a real server would abort; nothing to name
  canio::SdoMessage reply;
  reply.index = request->index;
  reply.subindex = request->subindex;
  auto abort = [&](uint32_t code) {
    ++counters_.sdo_aborts;
    reply.command = SdoCommand::Abort;
    reply.size = 0;
    reply.value = code;
  };
  if (uint32_t code = 0; serve_identity(*request, reply, code)) {
    if (code != 0) abort(code);
    if (auto frame = canio::build_sdo_response(config_.node, reply)) send(*frame);
    return;
  }
  if (request->index == canio::kHeartbeatProducerIndex && request->subindex == 0) {
    // The node's own object: the heartbeat producer time (u16, ms).
    if (request->command == SdoCommand::UploadRequest) {
      reply.command = SdoCommand::UploadResponse;
      reply.size = 2;
      reply.value = heartbeat_ms_;
    } else if (request->command == SdoCommand::DownloadRequest && request->size == 2) {
      reply.command = SdoCommand::DownloadResponse;
      heartbeat_ms_ = static_cast<uint16_t>(request->value);
      next_heartbeat_ns_ = now() + int64_t{heartbeat_ms_} * 1'000'000;
    } else {
      abort(request->command == SdoCommand::DownloadRequest ? sdo_abort::kTypeLength
                                                            : sdo_abort::kGeneral);
    }
    if (auto frame = canio::build_sdo_response(config_.node, reply)) send(*frame);
    return;
  }
  const auto where = mapping_.register_for({request->index, request->subindex});
  Ds1928Module* module = nullptr;
  if (where) {
    for (std::size_t i = 0; i < config_.modules.size(); ++i)
      if (config_.modules[i].slot == where->slot) module = modules_[i].get();
  }
  const uint8_t size = where ? register_size(where->reg).value_or(0) : uint8_t{0};
  const bool injected =
      config_.faults.abort_code != 0 && where && where->reg == config_.faults.abort_register &&
      (request->command == SdoCommand::UploadRequest ? config_.faults.abort_on_read
                                                     : config_.faults.abort_on_write);
  if (!module || size == 0) {
    abort(sdo_abort::kNoObject);
  } else if (injected) {
    abort(config_.faults.abort_code);
  } else if (request->command == SdoCommand::UploadRequest) {
    uint32_t value = 0;
    const RegisterInfo* info = find_register(where->reg);
    if (config_.faults.config_write_only && info && info->direction == RegisterDirection::Config) {
      abort(sdo_abort::kWriteOnly);
    } else if (auto ec = module->read_register(where->reg, size, value)) {
      abort(sdo_abort_for(ec));
    } else {
      reply.command = SdoCommand::UploadResponse;
      reply.size = config_.faults.widen_sdo_reads && size == 1 ? uint8_t{4} : size;
      reply.value = value;
      if (config_.faults.upload_size_not_indicated) {
        reply.size = 4;
        reply.size_indicated = false;
      }
    }
  } else if (request->command == SdoCommand::DownloadRequest) {
    if (request->size != size) {
      abort(sdo_abort::kTypeLength);
    } else if (auto ec = module->write_register(where->reg, size, request->value)) {
      abort(sdo_abort_for(ec));
    } else {
      reply.command = SdoCommand::DownloadResponse;
    }
  } else {
    abort(sdo_abort::kGeneral);
  }
  if (auto frame = canio::build_sdo_response(config_.node, reply)) send(*frame);
}

bool CanioNode::serve_identity(const canio::SdoMessage& request, canio::SdoMessage& reply,
                               uint32_t& abort_code) const {
  using canio::SdoCommand;
  if (request.index != 0x1000 && request.index != 0x1018) return false;
  const CanioNodeIdentity& id = config_.identity;
  // Strict (CiA 301): an object the node does not have, a subindex it does not have, a write to
  // a read-only object: each with its own abort code.
  if (!id.present) {
    abort_code = sdo_abort::kNoObject;
    return true;
  }
  const uint8_t highest = request.index == 0x1000 ? 0 : 4;
  if (request.subindex > highest) {
    abort_code = sdo_abort::kNoSubindex;
    return true;
  }
  if (request.command == SdoCommand::DownloadRequest) {
    abort_code = sdo_abort::kReadOnly;
    return true;
  }
  if (request.command != SdoCommand::UploadRequest) {
    abort_code = sdo_abort::kGeneral;
    return true;
  }
  reply.command = SdoCommand::UploadResponse;
  if (request.index == 0x1018 && request.subindex == 0) {
    reply.size = 1;  // highest subindex supported
    reply.value = 4;
    return true;
  }
  reply.size = 4;
  reply.value = request.index == 0x1000 ? id.device_type
                : request.subindex == 1 ? id.vendor_id
                : request.subindex == 2 ? id.product_code
                : request.subindex == 3 ? id.revision_no
                                        : id.serial_no;
  return true;
}

std::size_t CanioNode::service(int64_t deadline_ns) {
  service_faults();
  send_due();
  std::array<canio::CanFrame, 32> rx{};
  const canio::ReceiveResult r = port_.receive(rx, std::min(deadline_ns, next_due_ns()));
  for (std::size_t k = 0; k < r.count; ++k) {
    const canio::CanFrame& f = rx[k];
    if (f.error || f.extended || silent_) continue;
    if (f.id == canio::kNmtCobId) {
      if (auto m = canio::parse_nmt(f)) on_nmt(*m);
      continue;
    }
    const canio::NmtState state = nmt_.load();
    if (config_.sync_enabled && f.id == config_.sync_id) {
      if (state != canio::NmtState::Operational) {
        ++counters_.ignored_not_operational;  // no PDO outside OPERATIONAL (CiA 301)
        continue;
      }
      ++counters_.syncs;
      for (std::size_t i = 0; i < modules_.size(); ++i) answer(i, f.rx_time_ns);
      if (config_.faults.unexpected_id != 0) {
        const std::array<uint8_t, 8> junk{0xDE, 0xAD, 0xBE, 0xEF, 0, 0, 0, 0};
        send(canio::make_standard_frame(config_.faults.unexpected_id, junk));
      }
      continue;
    }
    if (f.id == canio::kSdoRequestBase + config_.node) {
      uint32_t drops = sdo_drops_.load();
      while (drops > 0 && !sdo_drops_.compare_exchange_weak(drops, drops - 1)) {
      }
      // SDO is served in pre-operational and operational, not when stopped (CiA 301).
      if (config_.faults.answer_sdo && drops == 0 && state != canio::NmtState::Stopped)
        serve_sdo(f);
      continue;
    }
    for (std::size_t i = 0; i < modules_.size(); ++i) {
      if (f.id != config_.modules[i].ids.output) continue;
      if (state != canio::NmtState::Operational) {
        ++counters_.ignored_not_operational;
        break;
      }
      ModuleOutputs out;
      if (!canio::unpack_output_object(f.payload(), out)) break;
      ++counters_.outputs;
      modules_[i]->apply_outputs(out);
      if (!config_.sync_enabled) answer(i, f.rx_time_ns);
      break;
    }
  }
  send_due();
  return r.count;
}

}  // namespace ds1928::sim
