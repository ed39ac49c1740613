// PowerlinkCn: PollResponse Chaining (EPSG DS 302-C) — SyncRequest/SyncResponse, the PRes after
// the PResMN at the assigned time, the fall-back to PReq/PRes when the PResMN stops coming.
#include <algorithm>

#include "powerlink/sync_frames.hpp"
#include "sim/powerlink_cn.hpp"

namespace ds1928::sim {

namespace pl = ds1928::powerlink;

void PowerlinkCn::leave_prc() noexcept {
  prc_mode_ = false;
  pres_time_first_ns_ = 0;
  pres_fallback_timeout_ns_ = 0;
  pres_mn_since_soc_ = false;
  prc_missing_ns_ = 0;
}

void PowerlinkCn::on_sync_request(std::span<const uint8_t> frame, int64_t now_ns) noexcept {
  auto req = pl::parse_sync_request(frame);
  if (!req) {
    ++stats_.bad_frames;
    return;
  }
  if (req->target != config_.node_id) {
    // A SyncRequest to another node: its SyncResponse will tell this node's distance to it
    // (SyncDelay, measured from the end of this SyncRequest).
    sync_prev_node_ = req->target;
    sync_prev_ns_ = now_ns;
    return;
  }
  using namespace pl::sync_control;
  if ((req->sync_control & kDestMacAddressValid) != 0 && req->dest_mac != config_.mac) return;
  ++stats_.sync_requests;
  // A node without the feature answers (it is asked for its timing) but does not chain.
  if (config_.prc_capable) {
    if ((req->sync_control & kPResTimeFirstValid) != 0)
      pres_time_first_ns_ = req->pres_time_first_ns;
    if ((req->sync_control & kPResFallBackTimeoutValid) != 0)
      pres_fallback_timeout_ns_ = req->pres_fallback_timeout_ns;
    if ((req->sync_control & kPResModeReset) != 0) {
      prc_mode_ = false;  // PResModeReset overrules PResModeSet
    } else if ((req->sync_control & kPResModeSet) != 0 && !prc_mode_) {
      prc_mode_ = true;
      pres_mn_since_soc_ = true;
      prc_missing_ns_ = 0;
    }
  }
  pl::SyncResponse res;
  res.sync_status =
      (pres_time_first_ns_ != 0 || prc_mode_ ? pl::sync_status::kPResTimeFirstValid : 0u) |
      (prc_mode_ ? pl::sync_status::kPResModeStatus : 0u);
  res.latency_ns = config_.response_time_ns;
  res.sync_node_number = sync_node_number_;
  res.sync_delay_ns = sync_delay_ns_;
  res.pres_time_first_ns = pres_time_first_ns_;
  auto len =
      pl::build_sync_response(tx_, pl::asnd_header(config_.mac, config_.node_id, pl::kNodeMn), res);
  if (!len) return;
  emit({tx_.data(), *len});
  ++stats_.asnd_sent;
}

void PowerlinkCn::on_foreign_sync_response(uint8_t src_node, int64_t now_ns) noexcept {
  if (src_node != sync_prev_node_ || sync_prev_node_ == 0) return;
  // From the end of the SyncRequest to the start of the SyncResponse: the arrival instants are
  // those of each frame's end, so the SyncResponse's own wire time comes off.
  const int64_t delay = now_ns - sync_prev_ns_ - pl::prc_frame_time_ns(0);
  sync_node_number_ = src_node;
  sync_delay_ns_ = static_cast<uint32_t>(std::clamp<int64_t>(delay, 0, UINT32_MAX));
  sync_prev_node_ = 0;
}

void PowerlinkCn::on_pres_mn(const pl::PRes& pres, int64_t now_ns) noexcept {
  ++stats_.pres_mn;
  pres_mn_since_soc_ = true;
  note_polled();
  // The outputs come from the PResMN through the RPDO that names the MN (a chained node gets no
  // PReq), taken only when the MN says they are valid and the node is operational.
  if (pres.ready && state_ == pl::NmtState::kOperational && outputs_from_pres_mn_) {
    for (HostedModule& m : modules_) {
      if (m.pres_mn_mapping == nullptr) continue;
      ModuleOutputs out;
      if (pl::read_outputs(pres.payload, *m.pres_mn_mapping, out)) m.module->apply_outputs(out);
    }
    ++stats_.pres_mn_outputs;
  }
  // The PRes leaves PResTimeFirst after the end of the PResMN (its arrival instant).
  send_pres(now_ns, pres_time_first_ns_);
}

void PowerlinkCn::check_prc_fallback(int64_t) noexcept {
  // PResFallBackTimeout: cycles (SoCs) without a PResMN for this long and the MN is taken to poll
  // with PReq again. Counted per SoC, so a stall of the MN (no SoC either) is no reason.
  if (!prc_mode_) return;
  if (pres_mn_since_soc_) {
    prc_missing_ns_ = 0;
  } else {
    prc_missing_ns_ += period_ns_;
  }
  pres_mn_since_soc_ = false;
  if (pres_fallback_timeout_ns_ == 0 ||
      prc_missing_ns_ <= static_cast<int64_t>(pres_fallback_timeout_ns_))
    return;
  ++stats_.prc_fallbacks;
  prc_mode_ = false;
}

}  // namespace ds1928::sim
