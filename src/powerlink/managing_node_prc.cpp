// ManagingNode: PollResponse Chaining (EPSG DS 302-C, docs/powerlink.md §PollResponse Chaining).
//
// A CN configured for PRC that advertises the PRC feature flag is not polled with PReq. While it
// is configured (boot step "configure"), the MN sets it up with SyncRequests, one per SoA:
//   1. measure: a SyncRequest to its predecessor in the chain (the next lower PRC node), then one
//      to the CN; the CN timed the predecessor's SyncResponse from the end of that SyncRequest
//      (SyncDelay) and reports it with its own latency. The relative propagation delay between
//      the two is SyncDelay minus the predecessor's latency, at least an inter-frame gap;
//   2. add: PResModeSet with its PRes time: the predecessor's PRes time + the predecessor's PRes
//      on the wire + that delay (the first PRC node: 0, right after the PResMN);
//   3. verify: the CN reports the PRes time it took.
// From the add on, the CN answers the PResMN each cycle; a missing PRes in the PRC slot counts
// against its loss-of-PRes threshold like a missing answer to a PReq. A missing or wrong
// SyncResponse is retried once, the second failure resets the CN.
#include <algorithm>
#include <string>
#include <system_error>
#include <vector>

#include "powerlink/managing_node.hpp"
#include "powerlink/managing_node_cn.hpp"
#include "powerlink/pdo_image.hpp"
#include "powerlink/sync_frames.hpp"

namespace ds1928::powerlink {

namespace {
// A relative propagation delay above this is the predecessor's software answering late, not the
// wire (5 µs: a kilometre of cable, or ten hubs): it is capped here, the raw value is reported.
constexpr uint32_t kMaxPropagationNs = 5000;
}  // namespace

bool ManagingNode::uses_prc(const Cn& cn) const noexcept {
  return cn.cfg.prc && !cn.st->prc_fallback;
}

bool ManagingNode::prc_setup_pending(const Cn& cn) const noexcept {
  // kOff in the writing pass of "configure": chained only once the CN took its configuration.
  return uses_prc(cn) && cn.prc_step != PrcStep::kOff && cn.prc_step != PrcStep::kActive;
}

bool ManagingNode::prc_wants_sync_request(const Cn& cn) const noexcept {
  if (cn.prc_wait || cn.st->boot == CnBootState::kReset || !cn.st->identified) return false;
  return cn.prc_step != PrcStep::kOff && cn.prc_step != PrcStep::kActive;
}

const ManagingNode::Cn* ManagingNode::prc_predecessor(const Cn& cn) const noexcept {
  const Cn* best = nullptr;
  for (const auto& p : cns_) {
    if (p.get() == &cn || !uses_prc(*p) || p->cfg.node_id >= cn.cfg.node_id) continue;
    if (!best || p->cfg.node_id > best->cfg.node_id) best = p.get();
  }
  return best;
}

uint16_t ManagingNode::expected_pres_size(const Cn& cn) const noexcept {
  if (cn.st->identified) return cn.st->pres_size;
  return cn.cfg.pres_size.value_or(cn.layout.pres_size);
}

uint32_t ManagingNode::prc_time_of(const Cn& cn) const noexcept {
  // The time the CN holds once added; before that, what it would get (the chain's times do not
  // depend on which nodes are up, so nodes joining later never shift the others).
  if (cn.st->prc && cn.st->prc_pres_time_ns != 0) return cn.st->prc_pres_time_ns;
  const Cn* pred = prc_predecessor(cn);
  if (!pred) return 0;
  const uint32_t propagation =
      cn.st->prc_propagation_ns != 0 ? cn.st->prc_propagation_ns : kInterFrameGapNs;
  return prc_time_of(*pred) + prc_frame_time_ns(expected_pres_size(*pred)) + propagation;
}

Result<std::size_t> ManagingNode::build_prc_sync_request(Cn& cn, std::span<uint8_t> out) noexcept {
  using namespace sync_control;
  SyncRequest req;
  req.mn_nmt_state = mn_state_;
  Cn* target = &cn;
  if (cn.prc_step == PrcStep::kMeasurePredecessor) {
    const Cn* pred = prc_predecessor(cn);
    if (pred && pred->st->identified) {
      target = const_cast<Cn*>(pred);  // NOLINT: one of cns_, owned here
      cn.prc_measured_to = pred->cfg.node_id;
    } else {
      cn.prc_step = PrcStep::kMeasure;  // nothing to measure against yet
      cn.prc_measured_to = 0;
    }
  }
  req.target = target->cfg.node_id;
  req.dest_mac = target->st->mac;
  req.sync_control = kDestMacAddressValid;
  if (cn.prc_step == PrcStep::kAdd) {
    const uint32_t time = prc_time_of(cn);
    req.sync_control |= kPResModeSet | kPResTimeFirstValid | kPResFallBackTimeoutValid;
    req.pres_time_first_ns = time;
    // Without a PResMN for two cycles the CN goes back to answering PReqs.
    req.pres_fallback_timeout_ns = 2 * config_.cycle_us * 1000;
    cn.st->prc_pres_time_ns = time;
    // From the next cycle on the CN answers the PResMN, whatever its SyncResponse says.
    cn.st->prc = true;
    cn.st->in_isochronous = true;
  }
  cn.prc_wait = true;
  soa_service_ = RequestedService::kSyncRequest;
  soa_target_ = req.target;
  return build_sync_request(out, soa_header(config_.mac), req);
}

void ManagingNode::on_sync_response(Cn& from, std::span<const uint8_t> data) noexcept {
  auto res = parse_sync_response(data);
  if (!res) {
    ++counters_.invalid_frames;
    return;
  }
  ++from.st->sync_responses;
  from.st->prc_latency_ns = res->latency_ns;
  // The answer of a predecessor measured for another CN moves that CN on.
  for (auto& p : cns_) {
    Cn& cn = *p;
    if (!cn.prc_wait || cn.prc_step != PrcStep::kMeasurePredecessor ||
        cn.prc_measured_to != from.cfg.node_id)
      continue;
    cn.prc_wait = false;
    cn.prc_step = PrcStep::kMeasure;
  }
  if (!from.prc_wait) return;
  Cn& cn = from;
  cn.prc_wait = false;
  switch (cn.prc_step) {
    case PrcStep::kMeasure: {
      const Cn* pred = prc_predecessor(cn);
      uint32_t propagation = kInterFrameGapNs;
      if (pred && cn.prc_measured_to == pred->cfg.node_id &&
          res->sync_node_number == pred->cfg.node_id) {
        cn.st->prc_predecessor = pred->cfg.node_id;
        cn.st->prc_sync_delay_ns = res->sync_delay_ns;
        const uint32_t latency = pred->st->prc_latency_ns;
        const uint32_t rel = res->sync_delay_ns > latency ? res->sync_delay_ns - latency : 0;
        propagation = std::clamp(rel, kInterFrameGapNs, kMaxPropagationNs);
      }
      cn.st->prc_propagation_ns = propagation;
      cn.prc_failures = 0;
      cn.prc_step = PrcStep::kAdd;
      break;
    }
    case PrcStep::kAdd:
      cn.prc_failures = 0;
      cn.prc_step = PrcStep::kVerify;
      break;
    case PrcStep::kVerify:
      if ((res->sync_status & sync_status::kPResModeStatus) == 0 ||
          res->pres_time_first_ns != cn.st->prc_pres_time_ns) {
        // The CN did not take the time (or the mode): it would answer out of its slot.
        reset_node(cn, make_error_code(MnError::kPrcSyncFailed));
        return;
      }
      cn.prc_failures = 0;
      cn.prc_step = PrcStep::kActive;
      start_next_sdo(cn);  // the configuration may be waiting for the chain
      break;
    default:
      break;
  }
}

void ManagingNode::on_sync_timeout(Cn& cn) noexcept {
  for (auto& p : cns_) {
    // A predecessor that did not answer: measure the CN without it.
    if (p->prc_wait && p->prc_step == PrcStep::kMeasurePredecessor &&
        p->prc_measured_to == cn.cfg.node_id) {
      p->prc_wait = false;
      p->prc_step = PrcStep::kMeasure;
      p->prc_measured_to = 0;
    }
  }
  if (!cn.prc_wait) return;
  cn.prc_wait = false;
  prc_failed(cn);
}

void ManagingNode::prc_failed(Cn& cn) noexcept {
  if (++cn.prc_failures >= 2) reset_node(cn, make_error_code(MnError::kPrcSyncFailed));
}

std::span<const uint8_t> ManagingNode::prc_nodes() const noexcept {
  return {prc_list_.data(), prc_count_};
}

void ManagingNode::place_prc_outputs() {
  // Each chained node's outputs in the PResMN, placed by node id (place_pres_mn_outputs()); the
  // node is told where by its RPDO for the PResMN (PDO_RxCommParam_01h NodeID_U8 = 240, its
  // mapping at those offsets), written in "configure" like its other objects.
  std::vector<PresMnNode> chained;
  for (const auto& cn : cns_)
    if (cn->cfg.prc) chained.push_back({cn->cfg.node_id, cn->layout.preq_size, 0});
  const std::size_t end = place_pres_mn_outputs(chained);
  if (end > kMaxIsoPayload)
    throw std::system_error(make_error_code(MnError::kModuleBlockOutsidePayload),
                            "PResMN: the outputs of the chained nodes take " + std::to_string(end) +
                                " bytes, more than the " + std::to_string(kMaxIsoPayload) +
                                "-byte payload");
  pres_mn_size_ = static_cast<uint16_t>(std::max<std::size_t>(config_.bus.pres_mn_size, end));
  for (const PresMnNode& p : chained) {
    Cn& cn = *find(p.node_id);
    cn.st->prc_outputs_offset = p.base;
    cn.st->prc_outputs_size = p.preq_size;
    if (p.preq_size == 0) continue;
    const auto entries = rpdo_mapping_of(
        cn.layout, cn.cfg.object_scheme.value_or(config_.bus.object_scheme), p.base);
    auto write = [&](uint16_t index, uint8_t sub, uint64_t value, std::size_t size) {
      ObjectOp op{OpKind::kObjectWrite,  index, sub, ValueSource::kData, 0,
                  cn.object_data.size(), size};
      op.prc_only = true;
      cn.object_ops.push_back(op);
      for (std::size_t b = 0; b < size; ++b)
        cn.object_data.push_back(static_cast<uint8_t>(value >> (8 * b)));
    };
    // DS 301: a mapping is written while disabled (NumberOfEntries 0), then enabled.
    write(obj::kRxPdoMappingPresMn, 0, 0, 1);
    for (std::size_t k = 0; k < entries.size(); ++k)
      write(obj::kRxPdoMappingPresMn, static_cast<uint8_t>(k + 1), entries[k].to_u64(), 8);
    write(obj::kRxPdoMappingPresMn, 0, entries.size(), 1);
    write(obj::kRxPdoCommPresMn, 1, kNodeMn, 1);
  }
}

Result<std::size_t> ManagingNode::build_pres_mn(std::span<uint8_t> out) noexcept {
  // RD only when the outputs of every chained node it stands for were written this cycle.
  bool written = true;
  for (std::size_t i = 0; i < prc_count_; ++i) {
    if (Cn* cn = find(prc_list_[i])) {
      cn->polled = true;
      written = written && cn->outputs_written;
    }
  }
  // The chained nodes' outputs, each where place_prc_outputs() put it (the driver wrote them
  // through preq_payload()); the PResMN is also the PRC CNs' time reference.
  PRes pres;
  pres.nmt_state = mn_state_;
  pres.ready = mn_state_ == NmtState::kOperational && written;
  pres.payload = std::span<const uint8_t>(pres_mn_.data(), pres_mn_size_);
  return build_pres(out, pres_header(config_.mac, kNodeMn), pres);
}

void ManagingNode::update_prc_slot() noexcept {
  uint64_t last_end = 0;
  uint32_t timeout_us = 0;
  for (std::size_t i = 0; i < prc_count_; ++i) {
    const Cn* cn = find(prc_list_[i]);
    if (!cn) continue;
    last_end = std::max<uint64_t>(
        last_end, uint64_t{cn->st->prc_pres_time_ns} + prc_frame_time_ns(expected_pres_size(*cn)));
    timeout_us = std::max(timeout_us, cn->cfg.pres_timeout_us);
  }
  prc_slot_ns_ = prc_count_ == 0 ? 0
                                 : static_cast<int64_t>(prc_frame_time_ns(pres_mn_size_) +
                                                        last_end + uint64_t{timeout_us} * 1000);
}

}  // namespace ds1928::powerlink
