#include "test_cn.hpp"

#include <algorithm>

namespace ds1928::powerlink::test {

TestCn::TestCn(uint8_t id, NodeImageLayout l)
    : node(id),
      mac{0x02, 0, 0, 0, 0, id},
      layout(l),
      server_({.own_node = id,
               .own_mac = {0x02, 0, 0, 0, 0, id},
               .client_node = kNodeMn,
               .timeout_ns = 2'000'000'000,
               .max_segment = kMaxSdoSegment - 4},
              *this,
              [this](std::span<const uint8_t> f) { sdo_out_.emplace_back(f.begin(), f.end()); }) {}

void TestCn::power_cycle() {
  state = NmtState::kNotActive;
  server_.reset();
  sdo_out_.clear();
  objects.clear();
}

uint32_t TestCn::read_object(uint16_t index, uint8_t sub, std::span<uint8_t> out,
                             std::size_t& size) noexcept {
  ++reads;
  auto it = objects.find({index, sub});
  if (it == objects.end()) return 0x06020000;
  size = std::min(out.size(), it->second.size());
  std::copy_n(it->second.begin(), size, out.begin());
  return 0;
}

uint32_t TestCn::write_object(uint16_t index, uint8_t sub, std::span<const uint8_t> data) noexcept {
  writes.emplace_back(index, sub);
  if (auto it = write_aborts.find({index, sub}); it != write_aborts.end()) return it->second;
  const bool communication = index >= 0x1000 && index <= 0x1FFF;
  if (!communication && (index < 0x2001 || index > 0x2010)) return 0x06020000;
  objects[{index, sub}].assign(data.begin(), data.end());
  return 0;
}

void TestCn::on_frame(std::span<const uint8_t> bytes, std::deque<std::vector<uint8_t>>& out) {
  auto frame = parse_frame(bytes);
  if (!frame) return;
  std::array<uint8_t, kMaxFrameSize> buf{};
  auto emit = [&](Result<std::size_t> len) {
    if (len) out.emplace_back(buf.begin(), buf.begin() + *len);
  };
  const FrameHeader& h = frame->header;
  if (const auto* soc = std::get_if<Soc>(&frame->message)) {
    last_relative_time_us = soc->relative_time_us;
    if (state == NmtState::kPreOperational1) state = NmtState::kPreOperational2;
    return;
  }
  if (const auto* preq = std::get_if<PReq>(&frame->message)) {
    if (h.dst_node != node || drop_pres) return;
    if (state == NmtState::kNotActive || state == NmtState::kPreOperational1) return;
    last_preq_ready = preq->ready;
    last_preq_ea = preq->exception_acknowledge;
    last_preq_payload.assign(preq->payload.begin(), preq->payload.end());
    if (layout.count > 0) (void)read_outputs(preq->payload, layout.modules[0], last_outputs);
    std::vector<uint8_t> payload(std::max<int>(0, layout.pres_size + pres_size_delta), 0);
    ModuleInputs in = inputs;
    in.pos_time_us = static_cast<uint32_t>(last_relative_time_us);
    for (const ModuleMapping& m : layout.mappings()) (void)write_inputs(payload, m, in);
    payload.insert(payload.begin() + std::min<std::size_t>(layout.pres_size, payload.size()),
                   pres_extra.begin(), pres_extra.end());
    PRes pres;
    pres.nmt_state = state;
    pres.ready = state == NmtState::kOperational && !pres_not_ready;
    pres.exception_new = exception_new;
    pres.request_count = static_cast<uint8_t>(std::min<std::size_t>(
        sdo_out_.size() + static_cast<std::size_t>(fake_request_count) + (nmt_request ? 1 : 0), 7));
    pres.priority = nmt_request ? 7 : 3;
    pres.payload = payload;
    emit(build_pres(buf, pres_header(mac, node), pres));
    if (hold_pres && !out.empty()) {
      held_pres.push_back(std::move(out.back()));
      out.pop_back();
    }
    return;
  }
  if (const auto* soa = std::get_if<SoA>(&frame->message)) {
    if (state == NmtState::kNotActive) state = NmtState::kPreOperational1;
    if (soa->target != node) return;
    const FrameHeader ah = asnd_header(mac, node, kNodeMn);
    switch (soa->service) {
      case RequestedService::kIdentRequest: {
        ++ident_requests;
        IdentResponse r;
        r.nmt_state = state;
        r.vendor_id = vendor_id;
        r.product_code = product_code;
        r.device_type = device_type;
        r.serial_no = serial_no;
        r.poll_in_size = layout.pres_size;
        r.poll_out_size = poll_out_size.value_or(layout.preq_size);
        // VerifyConfigurationDate/Time: the CN's 0x1020/1, /2 (0 when never written).
        const auto u32 = [this](uint8_t sub) {
          uint32_t v = 0;
          if (auto it = objects.find({0x1020, sub}); it != objects.end())
            for (std::size_t i = 0; i < std::min<std::size_t>(4, it->second.size()); ++i)
              v |= static_cast<uint32_t>(it->second[i]) << (8 * i);
          return v;
        };
        r.verify_conf_date = u32(1);
        r.verify_conf_time = u32(2);
        emit(build_ident_response(buf, ah, r));
        break;
      }
      case RequestedService::kStatusRequest: {
        ++status_requests;
        if (soa->exception_reset) ++exception_resets;
        er_seen.push_back(soa->exception_reset);
        if (ignore_status_requests) break;
        if (follow_er && soa->exception_reset != last_er) exception_clear = soa->exception_reset;
        last_er = soa->exception_reset;
        StatusResponse r;
        r.nmt_state = state;
        r.exception_new = exception_new;
        r.exception_clear = follow_er && exception_clear;
        emit(build_status_response(buf, ah, r, status_errors));
        break;
      }
      case RequestedService::kNmtRequestInvite:
        ++nmt_request_invites;
        if (nmt_request) {
          emit(build_nmt_request(buf, ah, *nmt_request));
          nmt_request.reset();
        }
        break;
      case RequestedService::kUnspecifiedInvite:
        if (!sdo_out_.empty()) {
          out.push_back(std::move(sdo_out_.front()));
          sdo_out_.pop_front();
        }
        break;
      default:
        break;
    }
    return;
  }
  if (const auto* asnd = std::get_if<Asnd>(&frame->message)) {
    if (h.dst_node != node && h.dst_node != kNodeBroadcast) return;
    if (const auto* cmd = std::get_if<NmtCommand>(&asnd->body)) {
      ++nmt_commands;
      nmt_log.push_back(static_cast<NmtCommandId>(cmd->command));
      switch (static_cast<NmtCommandId>(cmd->command)) {
        case NmtCommandId::kEnableReadyToOperate:
          if (state == NmtState::kPreOperational2 && !hold_ready_to_operate)
            state = NmtState::kReadyToOperate;
          break;
        case NmtCommandId::kStartNode:
          if (state == NmtState::kReadyToOperate) state = NmtState::kOperational;
          break;
        case NmtCommandId::kResetNode:
        case NmtCommandId::kResetCommunication:
          state = NmtState::kNotActive;
          server_.reset();
          sdo_out_.clear();
          break;
        case NmtCommandId::kResetConfiguration:
          state = NmtState::kNotActive;
          if (power_cycles_in_reset_configuration > 0) {
            --power_cycles_in_reset_configuration;
            objects.clear();
          }
          taken = objects;
          server_.reset();
          sdo_out_.clear();
          break;
        default:
          break;
      }
    } else if (const auto* sdo = std::get_if<Sdo>(&asnd->body)) {
      if (!ignore_sdo) server_.receive(*sdo, 0);
    }
  }
}

std::error_code MemoryLink::send(std::span<const uint8_t> frame) noexcept {
  if (log) sent_log.emplace_back(frame.begin(), frame.end());
  for (TestCn* cn : cns) cn->on_frame(frame, rx);
  if (on_send) on_send(frame);
  return {};
}

Received MemoryLink::receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept {
  if (rx.empty()) {
    if (on_idle_wait) on_idle_wait(deadline_ns);
    return {};
  }
  auto f = std::move(rx.front());
  rx.pop_front();
  std::copy(f.begin(), f.end(), buffer.begin());
  return {f.size(), 0, {}};
}

}  // namespace ds1928::powerlink::test
