#include "sim/powerlink_cn.hpp"

#include <time.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "core/sdo_abort.hpp"
#include "powerlink/pdo_image.hpp"
#include "powerlink/sync_frames.hpp"
#include "sim/sim_error.hpp"

namespace ds1928::sim {

namespace pl = ds1928::powerlink;
using pl::NmtState;

namespace {

// Error codes logged in the StatusResponse history (DS 301 DLL error codes).
constexpr uint16_t kErrorLossOfSoc = 0x8245;
constexpr uint16_t kErrorLossOfPReq = 0x8242;
constexpr uint16_t kEntryDll = pl::entry_type::kModeOccurred | pl::entry_type::kProfilePowerlink;
constexpr uint16_t kEntryVendor = pl::entry_type::kModeOccurred | pl::entry_type::kProfileVendor;

constexpr uint8_t kPriorityGeneric = 3;
constexpr uint8_t kPriorityNmtRequest = 7;

[[nodiscard]] bool is_cycling(NmtState s) noexcept {
  return s == NmtState::kPreOperational2 || s == NmtState::kReadyToOperate ||
         s == NmtState::kOperational || s == NmtState::kStopped;
}

}  // namespace

// The bus controller's object dictionary as the SDO server sees it: identity objects and the
// module registers through the (index, subindex) ↔ register mapping; the standard objects are
// CnObjectDictionary's (powerlink/standard_objects.hpp).
class PowerlinkCn::Objects final : public pl::SdoObjectAccess {
 public:
  explicit Objects(PowerlinkCn& cn) : cn_(cn) {}

  uint32_t read_object(uint16_t index, uint8_t subindex, std::span<uint8_t> out,
                       std::size_t& size) noexcept override {
    if (CnObjectDictionary::handles(index)) {
      // ERR_ErrorRegister_U8: byte 0 of the StatusResponse's static error bit field.
      cn_.comm_.set_error_register(static_cast<uint8_t>(cn_.errsig_.static_error_bits()));
      return cn_.comm_.read(index, subindex, out, size);
    }
    Ds1928Module* module = nullptr;
    uint16_t reg = 0;
    if (const uint32_t abort = locate(index, subindex, module, reg)) return abort;
    uint32_t value = 0;
    const uint8_t width = ds1928::register_size(reg).value_or(4);
    if (auto ec = module->read_register(reg, width, value)) return sdo_abort_for(ec);
    if (out.size() < width) return sdo_abort::kGeneral;
    for (uint8_t i = 0; i < width; ++i) out[i] = static_cast<uint8_t>(value >> (8 * i));
    size = width;
    return 0;
  }

  uint32_t write_object(uint16_t index, uint8_t subindex,
                        std::span<const uint8_t> data) noexcept override {
    if (CnObjectDictionary::handles(index)) return cn_.comm_.write(index, subindex, data);
    Ds1928Module* module = nullptr;
    uint16_t reg = 0;
    if (const uint32_t abort = locate(index, subindex, module, reg)) return abort;
    const uint8_t width = ds1928::register_size(reg).value_or(static_cast<uint8_t>(data.size()));
    if (data.size() != width || (width != 1 && width != 2 && width != 4))
      return sdo_abort::kTypeLength;
    uint32_t value = 0;
    for (std::size_t i = 0; i < data.size(); ++i)
      value |= static_cast<uint32_t>(data[i]) << (8 * i);
    if (auto ec = module->write_register(reg, width, value)) return sdo_abort_for(ec);
    return 0;
  }

 private:
  uint32_t locate(uint16_t index, uint8_t subindex, Ds1928Module*& module,
                  uint16_t& reg) const noexcept {
    const auto address = cn_.mapping_.register_for(SdoObject{index, subindex});
    if (!address) return sdo_abort::kNoObject;
    for (const HostedModule& m : cn_.modules_) {
      if (m.slot == address->slot) {
        module = m.module.get();
        reg = address->reg;
        return 0;
      }
    }
    return sdo_abort::kNoObject;  // no module in that slot
  }

  PowerlinkCn& cn_;
};

// NMT table: what each state does with the cyclic frames. ASnd (NMT commands, SDO) is handled
// the same in every powered state.
const PowerlinkCn::StateHandler& PowerlinkCn::handler() const noexcept {
  static const StateHandler kTable[] = {
      {NmtState::kNotActive, &PowerlinkCn::soc_activate, &PowerlinkCn::preq_ignore,
       &PowerlinkCn::soa_activate},
      {NmtState::kPreOperational1, &PowerlinkCn::soc_pre_op1, &PowerlinkCn::preq_ignore,
       &PowerlinkCn::soa_answer},
      {NmtState::kPreOperational2, &PowerlinkCn::soc_cycling, &PowerlinkCn::preq_answer,
       &PowerlinkCn::soa_answer},
      {NmtState::kReadyToOperate, &PowerlinkCn::soc_cycling, &PowerlinkCn::preq_answer,
       &PowerlinkCn::soa_answer},
      {NmtState::kOperational, &PowerlinkCn::soc_cycling, &PowerlinkCn::preq_answer,
       &PowerlinkCn::soa_answer},
      // STOPPED: no PRes, only the asynchronous services.
      {NmtState::kStopped, &PowerlinkCn::soc_cycling, &PowerlinkCn::preq_ignore,
       &PowerlinkCn::soa_answer},
  };
  static const StateHandler kSilent{NmtState::kOff, nullptr, &PowerlinkCn::preq_ignore,
                                    &PowerlinkCn::soa_ignore};
  for (const StateHandler& h : kTable)
    if (h.state == state_) return h;
  return kSilent;
}

OwnPdoMapping own_pdo_mapping(OwnMapping style, const pl::NodeImageLayout& layout,
                              const PdoObjectScheme& scheme) {
  OwnPdoMapping out;
  if (style == OwnMapping::kNone) return out;
  if (style == OwnMapping::kPacked) {
    out.tpdo = pl::tpdo_mapping_of(layout, scheme);
    out.rpdo = pl::rpdo_mapping_of(layout, scheme);
    return out;
  }
  auto entry = [](uint16_t index, uint8_t sub, std::size_t at, std::size_t bytes) {
    return pl::PdoMapEntry{index, sub, static_cast<uint16_t>(at * 8),
                           static_cast<uint16_t>(bytes * 8)};
  };
  const bool gap = style == OwnMapping::kGap;
  std::size_t in_at = gap ? 2 : 0, out_at = gap ? 1 : 0;  // gap: the payload starts with a hole
  for (const pl::ModuleMapping& m : layout.mappings()) {
    const auto in = static_cast<uint16_t>(scheme.input_index + m.slot);
    const auto outs = static_cast<uint16_t>(scheme.output_index + m.slot);
    if (!gap) {
      in_at = m.pres_offset;
      out_at = m.preq_offset;
    }
    // PosCycle first: PositionHW, PosCycle, PositionLW, PosTime, SDCLifeCount, ErrorInfo, ...
    std::vector<pl::SchemeRegister> order(pl::kSchemeInputs.begin(), pl::kSchemeInputs.end());
    if (!gap) std::rotate(order.begin() + 1, order.begin() + 3, order.begin() + 4);
    for (const pl::SchemeRegister& r : order) {
      out.tpdo.push_back(entry(in, r.subindex, in_at, r.bytes));
      in_at += r.bytes + (gap ? 1 : 0);
    }
    for (uint8_t b = 0; b < m.input_mtu; ++b) {
      out.tpdo.push_back(entry(in, static_cast<uint8_t>(pl::kSchemeRxByteFirstSub + b), in_at, 1));
      in_at += gap ? 2 : 1;
    }
    if (gap) {
      // AckErrorInfo, a hole, OutputSequence, TxByte1..MTU.
      out.rpdo.push_back(entry(outs, pl::kSchemeOutputs[1].subindex, out_at, 1));
      out_at += 2;
      out.rpdo.push_back(entry(outs, pl::kSchemeOutputs[0].subindex, out_at++, 1));
      for (uint8_t b = 0; b < m.output_mtu; ++b)
        out.rpdo.push_back(
            entry(outs, static_cast<uint8_t>(pl::kSchemeTxByteFirstSub + b), out_at++, 1));
    }
  }
  if (!gap) out.rpdo = pl::rpdo_mapping_of(layout, scheme);
  return out;
}

PowerlinkCn::PowerlinkCn(const PowerlinkCnConfig& config, FrameSink send)
    : config_(config),
      send_(std::move(send)),
      mapping_(config.sdo_overrides),
      rng_(config.faults.seed) {
  comm_.set_identity(config_.device_type, config_.vendor_id, config_.product_code,
                     config_.revision_no, config_.serial_no);
  std::vector<pl::ModuleSpec> specs;
  for (const PowerlinkCnModuleConfig& m : config_.modules) {
    specs.push_back(
        pl::ModuleSpec{m.slot, m.input_mtu, m.output_mtu, m.pres_offset, m.preq_offset});
    HostedModule hosted;
    hosted.slot = m.slot;
    hosted.module = std::make_unique<Ds1928Module>(FunctionModel::Standard, m.sim);
    modules_.push_back(std::move(hosted));
  }
  specs_ = specs;
  auto layout = pl::make_layout(specs);
  if (layout) {
    layout_ = *layout;
  } else {
    // An impossible module list leaves an empty image: the node still boots (and says so in
    // its IdentResponse sizes), which is what a misconfigured bus controller does.
    layout_ = pl::NodeImageLayout{};
  }
  for (HostedModule& m : modules_) m.mapping = layout_.find(m.slot);
  // Its own mapping: in the objects from power-up, taken at the first reset below (boot()).
  const OwnPdoMapping own = own_pdo_mapping(config_.own_mapping, layout_, config_.object_scheme);
  if (!comm_.set_own_mapping(pl::obj::kTxPdoMapping, own.tpdo) ||
      !comm_.set_own_mapping(pl::obj::kRxPdoMapping, own.rpdo))
    throw std::invalid_argument("own PDO mapping: more than " +
                                std::to_string(CnObjectDictionary::kMaxMapped) +
                                " entries per direction (fewer modules or smaller MTUs)");

  objects_ = std::make_unique<Objects>(*this);
  pl::SdoServerConfig sdo_config;
  sdo_config.own_node = config_.node_id;
  sdo_config.own_mac = config_.mac;
  sdo_ = std::make_unique<pl::SdoServer>(
      sdo_config, *objects_, [this](std::span<const uint8_t> frame) { queue_async(frame); });
  boot(0);
}

PowerlinkCn::~PowerlinkCn() = default;

void PowerlinkCn::set_faults(const PowerlinkCnFaults& faults) noexcept {
  config_.faults = faults;
  rng_.seed(faults.seed);
}

void PowerlinkCn::enter(NmtState next, int64_t now_ns) noexcept {
  if (next == state_) return;
  const NmtState from = state_;
  state_ = next;
  if (listener_) listener_(from, next, now_ns);
}

void PowerlinkCn::boot(int64_t now_ns) noexcept {
  // Power-up runs through the reset states to NOT_ACTIVE without waiting for anything.
  enter(NmtState::kInitialising, now_ns);
  reset(pl::NmtCommandId::kSwReset, now_ns);
}

bool PowerlinkCn::bind_mapping(const pl::PdoMappingLists& lists,
                               pl::NodeImageLayout& out) noexcept {
  pl::PdoBindIssue issue;
  bool bound = false;
  if (auto layout = pl::bind_pdo_mapping(lists, config_.object_scheme, specs_, issue)) {
    out = *layout;
    bound = true;
  }
  ++(bound ? stats_.mappings_taken : stats_.mappings_refused);
  return bound;
}

void PowerlinkCn::take_mapping() noexcept {
  std::array<pl::PdoMapEntry, CnObjectDictionary::kMaxMapped> tpdo{}, rpdo{};
  const std::size_t nt = comm_.mapping(pl::obj::kTxPdoMapping, tpdo);
  const std::size_t nr = comm_.mapping(pl::obj::kRxPdoMapping, rpdo);
  by_mapping_ = false;
  if (nt > 0) {
    pl::PdoMappingLists lists;
    lists.tpdo = std::span<const pl::PdoMapEntry>(tpdo.data(), nt);
    lists.rpdo = std::span<const pl::PdoMapEntry>(rpdo.data(), nr);
    by_mapping_ = bind_mapping(lists, mapped_layout_);
  }
  // PollResponse Chaining: an RPDO channel whose NodeID_U8 names the MN takes the PResMN.
  outputs_from_pres_mn_ = false;
  for (const auto& [comm, mapping_index] :
       {std::pair{pl::obj::kRxPdoCommPresMn, pl::obj::kRxPdoMappingPresMn},
        std::pair{pl::obj::kRxPdoComm, pl::obj::kRxPdoMapping}}) {
    if (outputs_from_pres_mn_ || comm_.rpdo_source(comm) != pl::kNodeMn) continue;
    const std::size_t n = comm_.mapping(mapping_index, rpdo);
    if (n == 0) continue;
    pl::PdoMappingLists lists;
    lists.rpdo = std::span<const pl::PdoMapEntry>(rpdo.data(), n);
    lists.rpdo_index = mapping_index;
    lists.outputs_only = true;
    outputs_from_pres_mn_ = bind_mapping(lists, pres_mn_layout_);
  }
  const pl::NodeImageLayout& use = layout();
  for (HostedModule& m : modules_) {
    m.mapping = use.find(m.slot);
    m.pres_mn_mapping = outputs_from_pres_mn_ ? pres_mn_layout_.find(m.slot) : nullptr;
  }
}

void PowerlinkCn::reset(pl::NmtCommandId command, int64_t now_ns) noexcept {
  ++stats_.resets;
  switch (command) {
    case pl::NmtCommandId::kResetNode:
    case pl::NmtCommandId::kSwReset:
      // Reset application: the modules take their bus-controller defaults again.
      enter(NmtState::kResetApplication, now_ns);
      for (HostedModule& m : modules_) m.module->power_up();
      [[fallthrough]];
    case pl::NmtCommandId::kResetCommunication:
      enter(NmtState::kResetCommunication, now_ns);
      break;
    case pl::NmtCommandId::kResetConfiguration:
      enter(NmtState::kResetConfiguration, now_ns);
      break;
    default:
      break;
  }
  // NMTResetNode/ResetCommunication take the communication objects back to their stored (else
  // default) values; NMTResetConfiguration is how an MN activates what it wrote: kept.
  if (command != pl::NmtCommandId::kResetConfiguration) comm_.reset_communication();
  // RESET_CONFIGURATION (which every reset passes): the DLL takes what the objects say now.
  dll_ = {comm_.pres_size(layout_.pres_size), comm_.preq_size(layout_.preq_size),
          comm_.multiplexed_cycle_count()};
  take_mapping();
  sdo_->reset();
  async_head_ = 0;
  async_count_ = 0;
  have_soc_ = false;
  period_ns_ = 0;
  last_soc_ns_ = 0;
  unobserved_since_soc_ns_ = 0;
  cycles_since_preq_ = 0;
  preq_interval_ = 0;
  loss_of_preq_counter_ = 0;
  pres_pending_ = false;
  mc_seen_ = false;
  last_mc_ = false;
  mux_pos_ = -1;
  mux_slot_pos_ = -1;
  leave_prc();
  sync_prev_node_ = 0;
  sync_node_number_ = 0;
  sync_delay_ns_ = 0;
  // EC=1 after every reset: the MN sees the reboot and initialises the signalling again.
  errsig_.reset();
  enter(NmtState::kNotActive, now_ns);
}

void PowerlinkCn::power_cycle(int64_t now_ns) noexcept {
  ++stats_.power_cycles;
  nmt_request_pending_ = false;
  powered_ = false;
  power_on_at_ns_ = now_ns + config_.power_off_ns;
  pres_pending_ = false;
  leave_prc();
  enter(NmtState::kOff, now_ns);
}

int64_t PowerlinkCn::next_deadline_ns() const noexcept {
  int64_t next = INT64_MAX;
  if (!powered_) next = power_on_at_ns_;
  if (pres_pending_) next = std::min(next, pres_due_ns_);
  return next;
}

void PowerlinkCn::tick(int64_t now_ns) noexcept {
  if (!powered_) {
    if (now_ns < power_on_at_ns_) return;
    powered_ = true;
    boot(now_ns);
    return;
  }
  if (pres_pending_ && now_ns >= pres_due_ns_) {
    pres_pending_ = false;
    emit({pres_frame_.data(), pres_pending_len_});
    ++stats_.pres_sent;
  }
  if (have_soc_ && is_cycling(state_)) {
    // Loss of SoC: the MN stopped cycling (or the link is gone); fall back and wait to be
    // booted again.
    const int64_t timeout = std::max<int64_t>(
        config_.soc_timeout_min_ns, static_cast<int64_t>(config_.soc_loss_periods) * period_ns_);
    if (now_ns - last_soc_ns_ - unobserved_since_soc_ns_ > timeout) {
      ++stats_.loss_of_soc;
      log_error(kErrorLossOfSoc, now_ns);
      have_soc_ = false;
      period_ns_ = 0;
      preq_interval_ = 0;
      enter(NmtState::kPreOperational1, now_ns);
    }
  }
  sdo_->tick(now_ns);
  tick_modules(now_ns);
}

void PowerlinkCn::note_own_stall(int64_t from_ns, int64_t to_ns) noexcept {
  if (to_ns <= from_ns) return;
  ++stats_.own_stalls;
  stats_.own_stall_max_ns = std::max(stats_.own_stall_max_ns, to_ns - from_ns);
  if (!have_soc_) return;
  // Only the part after the last SoC: a SoC that came during the stall (its kernel stamp inside
  // the span) already restarted the count.
  const int64_t unseen = to_ns - std::max(from_ns, last_soc_ns_);
  if (unseen > 0) unobserved_since_soc_ns_ += unseen;
}

void PowerlinkCn::receive(std::span<const uint8_t> frame, int64_t now_ns) noexcept {
  if (!powered_) {
    tick(now_ns);
    if (!powered_) return;
  }
  auto parsed = pl::parse_frame(frame);
  if (!parsed) {
    ++stats_.bad_frames;
    return;
  }
  if (pl::is_short_frame(frame.size())) ++stats_.short_frames;
  const pl::Frame& f = *parsed;
  const StateHandler& h = handler();
  if (const auto* soc = std::get_if<pl::Soc>(&f.message)) {
    ++stats_.soc;
    if (h.on_soc != nullptr) (this->*h.on_soc)(*soc, now_ns);
  } else if (const auto* preq = std::get_if<pl::PReq>(&f.message)) {
    if (f.header.dst_node != config_.node_id) return;
    ++stats_.preq;
    (this->*h.on_preq)(*preq, now_ns);
  } else if (const auto* soa = std::get_if<pl::SoA>(&f.message)) {
    ++stats_.soa;
    (this->*h.on_soa)(*soa, now_ns);
    if (soa->service == pl::RequestedService::kSyncRequest && state_ != NmtState::kNotActive)
      on_sync_request(frame, now_ns);
  } else if (const auto* pres = std::get_if<pl::PRes>(&f.message)) {
    // The PResMN: in PRC mode this node's trigger, in the states that answer a PReq.
    if (f.header.src_node == pl::kNodeMn && prc_mode_ && h.on_preq == &PowerlinkCn::preq_answer)
      on_pres_mn(*pres, now_ns);
  } else if (const auto* asnd = std::get_if<pl::Asnd>(&f.message)) {
    if (asnd->service == pl::AsndService::kSyncResponse && f.header.src_node != config_.node_id) {
      on_foreign_sync_response(f.header.src_node, now_ns);
      return;
    }
    if (f.header.dst_node != config_.node_id && f.header.dst_node != pl::kNodeBroadcast) return;
    if (f.header.src_node != pl::kNodeMn) return;
    on_asnd(f, now_ns);
  }
  // PRes of the other CNs: nothing to consume.
}

// ---- SoC ----------------------------------------------------------------------------------

void PowerlinkCn::note_soc_timing(const pl::Soc& soc, int64_t now_ns) noexcept {
  if (have_soc_) {
    const int64_t gap = now_ns - last_soc_ns_;
    // Smooth the learned period; a gap of more than 4 periods is a pause, not a period.
    if (period_ns_ == 0) {
      period_ns_ = gap;
    } else if (gap < 4 * period_ns_) {
      period_ns_ += (gap - period_ns_) / 8;
    }
  }
  have_soc_ = true;
  last_soc_ns_ = now_ns;
  unobserved_since_soc_ns_ = 0;
  soc_relative_us_ = soc.relative_time_us;
  // MC toggles at the start of each multiplexed cycle (EPSG DS 301).
  if (mc_seen_ && soc.multiplexed_cycle_completed != last_mc_) {
    mux_pos_ = 0;
  } else if (mux_pos_ >= 0) {
    ++mux_pos_;
  }
  mc_seen_ = true;
  last_mc_ = soc.multiplexed_cycle_completed;
  // NetTime from the earliest SoC arrival, not the latest (sim/nettime_anchor.hpp).
  net_anchor_.sample(now_ns - static_cast<int64_t>(soc.relative_time_us) * 1000);
}

void PowerlinkCn::soc_activate(const pl::Soc& soc, int64_t now_ns) noexcept {
  enter(NmtState::kPreOperational1, now_ns);
  soc_pre_op1(soc, now_ns);
}

void PowerlinkCn::soc_pre_op1(const pl::Soc& soc, int64_t now_ns) noexcept {
  note_soc_timing(soc, now_ns);
  enter(NmtState::kPreOperational2, now_ns);
}

void PowerlinkCn::soc_cycling(const pl::Soc& soc, int64_t now_ns) noexcept {
  note_soc_timing(soc, now_ns);
  tick_modules(now_ns);
  check_prc_fallback(now_ns);
  // Loss of PReq (in PRC mode: of the PResMN): polled before (interval learned) but not within that
  // interval this time.
  // Counted from READY_TO_OPERATE on (before, the MN may still be configuring the interval).
  if (loss_of_preq_counter_ > 0) --loss_of_preq_counter_;
  if (preq_interval_ != 0 &&
      (state_ == NmtState::kReadyToOperate || state_ == NmtState::kOperational)) {
    ++cycles_since_preq_;
    if (cycles_since_preq_ > preq_interval_) {
      cycles_since_preq_ = 0;
      count_loss_of_preq(now_ns);
    }
  }
}

// ---- PReq / PRes ----------------------------------------------------------------------------

void PowerlinkCn::count_loss_of_preq(int64_t now_ns) noexcept {
  ++stats_.loss_of_preq;
  loss_of_preq_counter_ += 8;
  if (config_.loss_of_preq_threshold != 0 &&
      loss_of_preq_counter_ >= config_.loss_of_preq_threshold) {
    loss_of_preq_counter_ = 0;
    log_error(kErrorLossOfPReq, now_ns);
  }
}

void PowerlinkCn::check_slot(int64_t now_ns) noexcept {
  // Strict (EPSG DS 301): a multiplexed CN is polled in its slot of every multiplexed cycle,
  // exactly once. Its slot is where it was first polled once READY_TO_OPERATE; a PReq in another
  // cycle of the multiplexed cycle is a PReq missing from its slot.
  const uint32_t n = dll_.multiplexed_cycle_count;
  if (n < 2 || mux_pos_ < 0 ||
      (state_ != NmtState::kReadyToOperate && state_ != NmtState::kOperational))
    return;
  const int pos = mux_pos_ % static_cast<int>(n);
  if (mux_slot_pos_ < 0) {
    mux_slot_pos_ = pos;
  } else if (pos != mux_slot_pos_) {
    ++stats_.preq_out_of_slot;
    count_loss_of_preq(now_ns);
  }
}

void PowerlinkCn::note_polled() noexcept {
  // Strict: the interval is the configured one (a multiplexed CN is told its MultiplCycleCnt),
  // not learned from the MN's PReqs.
  preq_interval_ = std::max<uint32_t>(1, dll_.multiplexed_cycle_count);
  cycles_since_preq_ = 0;
}

void PowerlinkCn::preq_answer(const pl::PReq& preq, int64_t now_ns) noexcept {
  check_slot(now_ns);
  note_polled();
  errsig_.on_preq(preq.exception_acknowledge);
  // Outputs are applied only when the MN says they are valid and the node is operational.
  if (preq.ready && state_ == NmtState::kOperational) {
    for (HostedModule& m : modules_) {
      if (m.mapping == nullptr) continue;
      ModuleOutputs out;
      if (pl::read_outputs(preq.payload, *m.mapping, out)) m.module->apply_outputs(out);
    }
  }
  send_pres(now_ns);
}

int64_t PowerlinkCn::software_response_delay(int64_t now_ns) noexcept {
  const PowerlinkCnResponse& r = config_.response;
  int64_t delay = 0;
  if (r.pres_latency_median_ns > 0) {
    const double d = static_cast<double>(r.pres_latency_median_ns) *
                     std::exp(r.pres_latency_sigma * normal_(rng_));
    delay = std::min(static_cast<int64_t>(d), r.pres_latency_max_ns);
  }
  if (r.ready_after_soc_ns > 0 && last_soc_ns_ != 0)
    delay = std::max(delay, last_soc_ns_ + r.ready_after_soc_ns - now_ns);
  return delay;
}

void PowerlinkCn::send_pres(int64_t now_ns, int64_t offset_ns) noexcept {
  tick_modules(now_ns);
  const PowerlinkCnFaults& faults = config_.faults;
  if (faults.drop_pres > 0.0 && uniform_(rng_) < faults.drop_pres) {
    ++stats_.pres_dropped;
    return;
  }
  std::array<uint8_t, pl::kMaxIsoPayload> payload{};
  // The size an MN configured (cycle timing /5, the TPDO mapping), else the modules' image; module
  // bytes beyond a smaller configured size are left out.
  std::size_t size = dll_.pres_size;
  for (const HostedModule& m : modules_) {
    if (m.mapping == nullptr) continue;
    (void)pl::write_inputs(std::span<uint8_t>(payload.data(), size), *m.mapping,
                           m.module->inputs());
  }
  if (faults.pres_size_delta != 0) {
    const long wrong = static_cast<long>(size) + faults.pres_size_delta;
    size = static_cast<std::size_t>(std::clamp<long>(wrong, 0, pl::kMaxIsoPayload));
  }
  pl::PRes pres;
  pres.nmt_state = state_;
  pres.ready = state_ == NmtState::kOperational && !faults.pres_not_ready;
  if (state_ == NmtState::kOperational && faults.pres_not_ready) ++stats_.pres_not_ready;
  pres.exception_new = errsig_.exception_new();
  pres.request_count = request_count();
  pres.priority = request_priority();
  pres.payload = std::span<const uint8_t>(payload.data(), size);
  auto len = pl::build_pres(tx_, pl::pres_header(config_.mac, config_.node_id), pres);
  if (!len) return;
  int64_t due = now_ns + offset_ns + software_response_delay(now_ns);
  if (faults.delay_pres > 0.0 && faults.delay_pres_ns > 0 && uniform_(rng_) < faults.delay_pres)
    due += faults.delay_pres_ns;
  if (due > now_ns) {
    if (due - offset_ns > now_ns) ++stats_.pres_delayed;
    std::memcpy(pres_frame_.data(), tx_.data(), *len);
    pres_pending_len_ = *len;
    pres_due_ns_ = due;
    pres_pending_ = true;
    return;
  }
  emit({tx_.data(), *len});
  ++stats_.pres_sent;
}

// ---- SoA / ASnd -----------------------------------------------------------------------------

void PowerlinkCn::soa_activate(const pl::SoA& soa, int64_t now_ns) noexcept {
  enter(NmtState::kPreOperational1, now_ns);
  soa_answer(soa, now_ns);
}

void PowerlinkCn::soa_answer(const pl::SoA& soa, int64_t now_ns) noexcept {
  (void)now_ns;
  if (soa.target != config_.node_id) return;
  switch (soa.service) {
    case pl::RequestedService::kIdentRequest:
      send_ident_response();
      break;
    case pl::RequestedService::kStatusRequest:
      // ER/EA of this request first: the answer carries the EC it asks for.
      errsig_.on_status_request(soa.exception_reset, soa.exception_acknowledge);
      send_status_response();
      break;
    case pl::RequestedService::kUnspecifiedInvite:
      if (async_count_ != 0) {
        emit({async_frames_[async_head_].data(), async_len_[async_head_]});
        ++stats_.asnd_sent;
        async_head_ = (async_head_ + 1) % kAsyncSlots;
        --async_count_;
      }
      break;
    case pl::RequestedService::kNmtRequestInvite:
      if (nmt_request_pending_) {
        pl::NmtRequest request;
        request.command = static_cast<uint8_t>(pl::NmtCommandId::kResetNode);
        request.target = config_.node_id;
        auto len = pl::build_nmt_request(
            tx_, pl::asnd_header(config_.mac, config_.node_id, pl::kNodeMn), request);
        if (len) {
          emit({tx_.data(), *len});
          ++stats_.nmt_requests_sent;
          nmt_request_pending_ = false;
        }
      }
      break;
    default:
      // SyncRequest: no sync support.
      break;
  }
}

void PowerlinkCn::on_asnd(const pl::Frame& frame, int64_t now_ns) noexcept {
  const auto& asnd = std::get<pl::Asnd>(frame.message);
  if (const auto* cmd = std::get_if<pl::NmtCommand>(&asnd.body)) {
    ++stats_.nmt_commands;
    on_nmt_command(cmd->command, now_ns);
  } else if (const auto* sdo = std::get_if<pl::Sdo>(&asnd.body)) {
    if (state_ == NmtState::kNotActive) return;  // SDO needs PRE_OPERATIONAL_1 or later
    ++stats_.sdo_frames_in;
    if (sdo->sequence.send_con == pl::SdoSendCon::kInit) {
      // A new connection: answers still queued for the old one would end it when they go out.
      async_head_ = 0;
      async_count_ = 0;
    }
    sdo_->receive(*sdo, now_ns);
  }
}

void PowerlinkCn::on_nmt_command(uint8_t command, int64_t now_ns) noexcept {
  using C = pl::NmtCommandId;
  switch (static_cast<C>(command)) {
    case C::kStartNode:
      if (state_ == NmtState::kReadyToOperate) enter(NmtState::kOperational, now_ns);
      break;
    case C::kStopNode:
      if (is_cycling(state_)) enter(NmtState::kStopped, now_ns);
      break;
    case C::kEnterPreOperational2:
      if (state_ == NmtState::kOperational || state_ == NmtState::kReadyToOperate ||
          state_ == NmtState::kStopped) {
        enter(NmtState::kPreOperational2, now_ns);
      }
      break;
    case C::kEnableReadyToOperate:
      if (state_ == NmtState::kPreOperational2) enter(NmtState::kReadyToOperate, now_ns);
      break;
    case C::kResetNode:
    case C::kSwReset:
    case C::kResetCommunication:
    case C::kResetConfiguration:
      reset(static_cast<C>(command), now_ns);
      break;
    default:
      break;  // not a command for a CN in this state: ignored, as the standard says
  }
}

void PowerlinkCn::send_ident_response() noexcept {
  pl::IdentResponse ident;
  ident.nmt_state = state_;
  ident.exception_new = errsig_.exception_new();
  ident.request_count = request_count();
  ident.priority = request_priority();
  ident.mtu = 300;
  ident.poll_in_size = dll_.pres_size;
  ident.poll_out_size = dll_.preq_size;
  ident.response_time_ns = config_.response_time_ns;
  ident.device_type = config_.device_type;
  ident.vendor_id = config_.vendor_id;
  ident.product_code = config_.product_code;
  ident.revision_no = config_.revision_no;
  ident.serial_no = config_.serial_no;
  ident.verify_conf_date = comm_.configuration_date();
  ident.verify_conf_time = comm_.configuration_time();
  // Feature flags: SDO by ASnd (bit 2) and NMT Info services (bit 3), PRC (bit 18) when
  // configured — no PDO over SDO.
  ident.feature_flags = (1u << 2) | (1u << 3) | (config_.prc_capable ? pl::kFeatureFlagPrc : 0u);
  ident.ip_address =
      192u | (168u << 8) | (100u << 16) | (static_cast<uint32_t>(config_.node_id) << 24);
  ident.subnet_mask = 0x00FFFFFF;
  ident.default_gateway = 192u | (168u << 8) | (100u << 16) | (254u << 24);
  const char name[] = "ds1928-sim";
  std::memcpy(ident.host_name.data(), name, sizeof name - 1);
  auto len = pl::build_ident_response(
      tx_, pl::asnd_header(config_.mac, config_.node_id, pl::kNodeMn), ident);
  if (!len) return;
  emit({tx_.data(), *len});
  ++stats_.asnd_sent;
}

void PowerlinkCn::send_status_response() noexcept {
  pl::StatusResponse status;
  status.nmt_state = state_;
  status.exception_new = errsig_.exception_new();
  status.exception_clear = errsig_.exception_clear();
  status.request_count = request_count();
  status.priority = request_priority();
  status.static_error_bits = errsig_.static_error_bits();
  auto len = pl::build_status_response(
      tx_, pl::asnd_header(config_.mac, config_.node_id, pl::kNodeMn), status, errsig_.entries());
  if (!len) return;
  emit({tx_.data(), *len});
  ++stats_.asnd_sent;
  // Kept until the MN acknowledges them with EA.
  errsig_.status_sent();
}

void PowerlinkCn::queue_async(std::span<const uint8_t> frame) noexcept {
  if (async_count_ == kAsyncSlots || frame.size() > pl::kMaxFrameSize) return;  // SDO retries
  const std::size_t slot = (async_head_ + async_count_) % kAsyncSlots;
  std::memcpy(async_frames_[slot].data(), frame.data(), frame.size());
  async_len_[slot] = frame.size();
  ++async_count_;
}

uint8_t PowerlinkCn::request_count() const noexcept {
  return static_cast<uint8_t>(
      std::min<std::size_t>(async_count_ + (nmt_request_pending_ ? 1 : 0), 7));
}

uint8_t PowerlinkCn::request_priority() const noexcept {
  if (nmt_request_pending_) return kPriorityNmtRequest;
  return async_count_ != 0 ? kPriorityGeneric : 0;
}

void PowerlinkCn::log_error(uint16_t code, int64_t now_ns) noexcept {
  queue_error(kEntryDll, code, {}, now_ns);
}

void PowerlinkCn::raise_error(uint16_t code, const std::array<uint8_t, 8>& info,
                              int64_t now_ns) noexcept {
  if (!powered_) return;
  queue_error(kEntryVendor, code, info, now_ns);
}

void PowerlinkCn::queue_error(uint16_t type, uint16_t code, const std::array<uint8_t, 8>& info,
                              int64_t now_ns) noexcept {
  pl::ErrorEntry e;
  e.type = type;
  e.code = code;
  e.additional = info;
  const uint64_t net_us = net_time_us_at(now_ns);
  e.timestamp = (net_us / 1'000'000) | (((net_us % 1'000'000) * 1000) << 32);
  errsig_.queue(e);
  ++stats_.errors_raised;
}

// ---- Time and modules ---------------------------------------------------------------------

uint64_t PowerlinkCn::net_time_us_at(int64_t now_ns) const noexcept {
  const std::optional<int64_t> offset = net_anchor_.offset();
  if (!offset) return static_cast<uint64_t>(now_ns / 1000);
  return pl::net_time_us(static_cast<uint64_t>((now_ns - *offset) / 1000),
                         config_.nettime_offset_us);
}

void PowerlinkCn::tick_modules(int64_t now_ns) noexcept {
  const uint64_t net = net_time_us_at(now_ns);
  for (HostedModule& m : modules_) m.module->tick(now_ns, net);
}

void PowerlinkCn::emit(std::span<const uint8_t> frame) noexcept {
  if (send_) send_(frame);
}

}  // namespace ds1928::sim
