// ManagingNode: SDO transfers (boot configuration, identity check, clients' register requests).
#include <algorithm>
#include <cstring>

#include "core/sdo_abort.hpp"
#include "powerlink/managing_node.hpp"
#include "powerlink/managing_node_cn.hpp"
#include "powerlink/pdo_image.hpp"

namespace ds1928::powerlink {

// ---- SDO
// ------------------------------------------------------------------------------------------

bool ManagingNode::submit(uint8_t node, uint8_t slot, const RegisterRequest& request) noexcept {
  if (!can_submit(node)) return false;
  Cn* cn = find(node);
  cn->ops[(cn->ops_head + cn->ops_count) % kOpQueueDepth] = {slot, request};
  ++cn->ops_count;
  start_next_sdo(*cn);
  return true;
}

std::size_t ManagingNode::requests_in_flight() const noexcept {
  std::size_t n = 0;
  for (const auto& cn : cns_) n += cn->ops_count + (cn->op_active && !cn->op_internal ? 1 : 0);
  return n;
}

bool ManagingNode::can_submit(uint8_t node) const noexcept {
  const Cn* cn = find(node);
  return cn != nullptr && cn->ops_count < kOpQueueDepth &&
         results_count_ + requests_in_flight() < results_.size();
}

void ManagingNode::push_result(const RegisterResult& r) noexcept {
  // Room is certain: submit() accepted the request only while it had one.
  results_[(results_head_ + results_count_++) % results_.size()] = r;
}

bool ManagingNode::poll(RegisterResult& out) noexcept {
  if (results_count_ == 0) return false;
  out = results_[results_head_];
  results_head_ = (results_head_ + 1) % results_.size();
  --results_count_;
  return true;
}

void ManagingNode::start_next_sdo(Cn& cn) noexcept {
  while (!cn.op_active) {
    const CnBootState b = cn.st->boot;
    if (b == CnBootState::kIdentify || b == CnBootState::kReset ||
        b == CnBootState::kResetConfiguration)
      return;
    if (cn.configuring && cn.object_next < cn.object_ops.size()) {
      if (cn.object_ops[cn.object_next].prc_only && !uses_prc(cn)) {
        ++cn.object_next;
        continue;
      }
      start_object_op(cn);
      continue;
    }
    if (cn.configuring && cn.map_read != MapRead::kDone) {
      start_mapping_read(cn);
      continue;
    }
    if (cn.configuring && cn.boot_next < cn.boot_ops.size()) {
      cn.current = cn.boot_ops[cn.boot_next];
      cn.op_internal = true;
      cn.op_kind = OpKind::kRegister;
    } else if (cn.configuring) {
      // A PRC node is configured once its chain set-up is done too (managing_node_prc.cpp).
      if (prc_setup_pending(cn)) return;
      cn.configuring = false;
      if (!cn.config_applied && cn.written > 0) {
        // Objects were written: NMTResetConfiguration makes the CN take them (EPSG DS 301).
        enter(cn, CnBootState::kResetConfiguration);
        return;
      }
      if (!cn.config_applied && uses_prc(cn)) {
        // Nothing was taken (every write refused): chain the PRC node without a reset.
        cn.config_applied = true;
        enter(cn, CnBootState::kConfigure);
        return;
      }
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
    const auto object = mapping_.object_for(cn.current.slot, cn.current.request.reg);
    if (!object) {
      sdo_done(cn, make_error_code(SdoError::kNoMapping), {});
      continue;
    }
    cn.op_active = true;
    std::error_code ec;
    if (cn.current.request.write) {
      std::array<uint8_t, 4> bytes{};
      store_le32(bytes.data(), cn.current.request.value);
      ec = cn.sdo->write(
          object->index, object->subindex,
          std::span<const uint8_t>(bytes.data(), std::min<std::size_t>(cn.current.request.size, 4)),
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
    ++cn.written;
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
  // kConnectionLost: the node is being reset, and its last error is the reset's reason (set
  // before the reset ended this transfer), not this consequence of it.
  if (cn.op_internal && cn.op_kind != OpKind::kRegister) {
    if (ec == SdoError::kConnectionLost) return;
    if (ec) cn.st->last_error = ec;
    if (cn.op_kind == OpKind::kMappingRead)
      mapping_read_done(cn, ec, data);
    else
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
    if (ec != SdoError::kConnectionLost) cn.st->last_error = ec;
  } else if (cn.op_internal && cn.current.request.write) {
    ++cn.written;
  }
  if (cn.op_internal) {
    // A setting the bus controller refuses is reported (status) but does not stop the boot.
    ++cn.boot_next;
  } else {
    push_result({cn.current.request.tag, ec, value});
  }
  if (ec == SdoError::kConnectionLost) return;  // the node is being reset
  start_next_sdo(cn);
}

}  // namespace ds1928::powerlink
