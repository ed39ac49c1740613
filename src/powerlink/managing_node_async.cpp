// ManagingNode: the asynchronous slot (SoA grants, the MN's own ASnd, CN ASnd answers) and error
// signalling.
#include <algorithm>
#include <cstring>

#include "powerlink/managing_node.hpp"
#include "powerlink/managing_node_cn.hpp"
#include "powerlink/sync_frames.hpp"

namespace ds1928::powerlink {

// ---- Asynchronous slot -------------------------------------------------------------------------

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
        default: {
          const bool resetting =
              cn.st->boot == CnBootState::kReset || cn.st->boot == CnBootState::kResetConfiguration;
          if (prc_wants_sync_request(cn)) {
            prc_sync_from_ = &cn;  // the SoA is the SyncRequest (build_prc_sync_request)
            soa_service_ = RequestedService::kSyncRequest;
            soa_target_ = cn.cfg.node_id;
            return true;
          }
          if (cn.st->boot == CnBootState::kIdentify) {
            soa_service_ = RequestedService::kIdentRequest;
          } else if (resetting) {
            break;  // no answer to expect while it resets (NMTResetNode, ResetConfiguration)
          } else if (cn.errsig.status_request_due()) {
            // The error signalling handshake, or EN toggled: whatever the boot state.
            soa_service_ = RequestedService::kStatusRequest;
            cn.last_status_request = counters_.cycles;
          } else if (counters_.cycles - cn.last_status_request >=
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
    }
    return false;
  };
  if (n > 0) {
    const int first = static_cast<int>(counters_.cycles % 3);
    for (int i = 0; i < 3; ++i)
      if (pick((first + i) % 3)) break;
    async_rr_ = (async_rr_ + 1) % n;
  }
  if (soa_service_ == RequestedService::kSyncRequest && prc_sync_from_ != nullptr) {
    Cn& cn = *prc_sync_from_;
    prc_sync_from_ = nullptr;
    auto len = build_prc_sync_request(cn, out);  // may address the CN's predecessor
    awaiting_asnd_ = true;
    return len;
  }
  awaiting_asnd_ = soa_service_ != RequestedService::kNone && soa_target_ != kNodeMn;
  SoA soa;
  soa.mn_nmt_state = mn_state_;
  soa.service = soa_service_;
  soa.target = soa_target_;
  if (soa_service_ == RequestedService::kStatusRequest) {
    if (Cn* t = find(soa_target_)) {
      soa.exception_acknowledge = t->errsig.exception_acknowledge();
      soa.exception_reset = t->errsig.exception_reset();
      t->errsig.on_status_request_sent();
      sync_errsig(*t);
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
  if (awaiting_asnd_ && soa_service_ == RequestedService::kSyncRequest) {
    if (Cn* cn = find(soa_target_)) on_sync_timeout(*cn);
  }
  if (awaiting_asnd_) {
    const bool mandatory = soa_service_ == RequestedService::kIdentRequest ||
                           soa_service_ == RequestedService::kStatusRequest;
    ++(mandatory ? counters_.async_timeouts : counters_.async_invites_unused);
  }
  awaiting_asnd_ = false;
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
      // Identified with the download applied: only after this MN's NMTResetConfiguration (every
      // other way back to "identify" passes reset_node, which clears config_applied).
      if (cn->config_applied) verify_configuration(*cn, *ident);
      cn->st->identified = true;
      cn->st->mac = h.src_mac;
      cn->st->vendor_id = ident->vendor_id;
      cn->st->product_code = ident->product_code;
      cn->st->preq_size =
          c.preq_size.value_or(ident->poll_out_size ? ident->poll_out_size : cn->layout.preq_size);
      cn->st->pres_size =
          c.pres_size.value_or(ident->poll_in_size ? ident->poll_in_size : cn->layout.pres_size);
      cn->st->preq_size = std::min<uint16_t>(cn->st->preq_size, kMaxIsoPayload);
      // PRC needs the CN's feature (EPSG DS 302-C): without it the CN is polled with PReq/PRes,
      // and says so in status (openPOWERLINK's MN handles such a CN as async-only instead).
      const bool fallback = c.prc && (ident->feature_flags & kFeatureFlagPrc) == 0;
      if (fallback) cn->st->last_error = make_error_code(MnError::kPrcNotSupported);
      cn->st->prc_fallback = fallback;
      std::fill(cn->preq.begin(), cn->preq.end(), 0);
      // Error signalling starts afresh: ER=1 until EC=1, then ER=0 until EC=0.
      cn->errsig.restart();
      sync_errsig(*cn);
      enter(*cn, CnBootState::kWaitPreOp2);
    }
    reported_state(*cn, ident->nmt_state);
  } else if (const auto* status = std::get_if<StatusResponse>(&asnd.body)) {
    cn->rs = status->request_count;
    cn->pr = status->priority;
    cn->st->static_error_bits = status->static_error_bits;
    // New entries (EN toggled against EA) are recorded; EA then follows EN.
    if (cn->errsig.on_status_response(status->exception_new, status->exception_clear))
      record_error_entries(*cn, *status);
    cn->st->exception_new = status->exception_new;
    sync_errsig(*cn);
    reported_state(*cn, status->nmt_state);
  } else if (const auto* sdo = std::get_if<Sdo>(&asnd.body)) {
    if (h.dst_node != kNodeMn) return;
    cn->sdo_wait_answer = false;
    cn->sdo->receive(*sdo, now_ns_);
  } else if (const auto* request = std::get_if<NmtRequest>(&asnd.body)) {
    handle_nmt_request(*cn, *request);
  } else if (asnd.service == AsndService::kSyncResponse) {
    on_sync_response(*cn, std::get<AsndRaw>(asnd.body).data);
  } else {
    // Services this MN does not use (manufacturer-specific): accepted, and the
    // invitation is not repeated until the CN announces a request again.
    cn->rs = 0;
  }
}

void ManagingNode::verify_configuration(Cn& cn, const IdentResponse& ident) noexcept {
  // EPSG DS 301's configuration check (CFM), as openPOWERLINK's MN runs it at each boot: the
  // download writes 0x1020/1, /2; a CN that took it reports them in its IdentResponse. One that
  // was power-cycled while it reset (or dropped the objects) reports its stored or default values
  // and would otherwise be started with them: the next configure step writes everything again.
  const auto& c = cn.cfg;
  if (!c.expected_conf_date && !c.expected_conf_time) return;
  if (ident.verify_conf_date == c.expected_conf_date.value_or(0) &&
      ident.verify_conf_time == c.expected_conf_time.value_or(0))
    return;
  cn.config_applied = false;
  ++cn.st->configuration_not_verified;
  cn.st->last_error = make_error_code(MnError::kConfigurationNotVerified);
}

void ManagingNode::note_exception_new(Cn& cn, bool en) noexcept {
  cn.st->exception_new = en;
  const bool was = cn.errsig.fetch_pending();
  cn.errsig.on_exception_new(en);
  if (!was && cn.errsig.fetch_pending()) ++cn.st->exceptions_signalled;
}

void ManagingNode::sync_errsig(Cn& cn) noexcept {
  CnStatus& st = *cn.st;
  st.errsig = cn.errsig.state();
  st.errsig_handshakes = cn.errsig.handshakes();
  st.errsig_gave_up = cn.errsig.gave_up();
  st.exception_acknowledge = cn.errsig.exception_acknowledge();
}

void ManagingNode::record_error_entries(Cn& cn, const StatusResponse& status) noexcept {
  CnStatus& st = *cn.st;
  for (std::size_t i = 0; i < status.entry_count(); ++i) {
    const ErrorEntry e = status.entry(i);
    // Status entries describe a current state, re-sent with every answer: only the emergency
    // queue's entries are events to record.
    if ((e.type & entry_type::kStatus) != 0) continue;
    if (st.error_entry_count == st.error_entries.size()) {
      std::move(st.error_entries.begin() + 1, st.error_entries.end(), st.error_entries.begin());
      --st.error_entry_count;
    }
    st.error_entries[st.error_entry_count++] = e;
    ++st.status_error_entries;
    st.last_error_code = e.code;
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

}  // namespace ds1928::powerlink
