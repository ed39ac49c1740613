#include "powerlink/frames.hpp"

#include <algorithm>
#include <cstring>

namespace ds1928::powerlink {
namespace {

constexpr std::size_t kTypeOffset = 14;
constexpr std::size_t kDstNodeOffset = 15;
constexpr std::size_t kSrcNodeOffset = 16;

// SoC/PReq/PRes/SoA flag bits.
constexpr uint8_t kFlagMc = 0x80;
constexpr uint8_t kFlagPs = 0x40;
constexpr uint8_t kFlagMs = 0x20;
constexpr uint8_t kFlagEn = 0x10;
constexpr uint8_t kFlagEc = 0x08;
constexpr uint8_t kFlagEa = 0x04;
constexpr uint8_t kFlagEr = 0x02;
constexpr uint8_t kFlagRd = 0x01;

constexpr uint8_t kSdoResponse = 0x80;
constexpr uint8_t kSdoAbort = 0x40;

[[nodiscard]] constexpr uint8_t pr_rs(uint8_t priority, uint8_t request_count) noexcept {
  return static_cast<uint8_t>(((priority & 0x07) << 3) | (request_count & 0x07));
}

// Zeroes the frame area and writes the 17-byte header; nullptr when `out` is too small.
uint8_t* begin_frame(std::span<uint8_t> out, std::size_t content, const FrameHeader& h,
                     MessageType type, std::size_t& length) noexcept {
  length = std::max(content, kMinFrameSize);
  if (length > kMaxFrameSize || out.size() < length) return nullptr;
  uint8_t* p = out.data();
  std::memset(p, 0, length);
  std::memcpy(p, h.dst_mac.data(), 6);
  std::memcpy(p + 6, h.src_mac.data(), 6);
  p[12] = static_cast<uint8_t>(kEtherType >> 8);
  p[13] = static_cast<uint8_t>(kEtherType & 0xFF);
  p[kTypeOffset] = static_cast<uint8_t>(type);
  p[kDstNodeOffset] = h.dst_node;
  p[kSrcNodeOffset] = h.src_node;
  return p;
}

[[nodiscard]] bool is_cn(uint8_t node) noexcept {
  return node >= 1 && node <= kNodeMaxCn;
}

[[nodiscard]] bool is_valid_requested_service(uint8_t v) noexcept {
  switch (static_cast<RequestedService>(v)) {
    case RequestedService::kNone:
    case RequestedService::kIdentRequest:
    case RequestedService::kStatusRequest:
    case RequestedService::kNmtRequestInvite:
    case RequestedService::kSyncRequest:
    case RequestedService::kUnspecifiedInvite:
      return true;
  }
  return false;
}

Result<Soc> decode_soc(std::span<const uint8_t> f, const FrameHeader& h) noexcept {
  if (f.size() < kSocSize) return FrameError::kSocTruncated;
  if (h.src_node != kNodeMn) return FrameError::kInvalidSourceNode;
  if (h.dst_node != kNodeBroadcast) return FrameError::kInvalidDestinationNode;
  Soc s;
  s.multiplexed_cycle_completed = (f[18] & kFlagMc) != 0;
  s.prescaled_slot = (f[18] & kFlagPs) != 0;
  s.net_time.seconds = load_le32(&f[20]);
  s.net_time.nanoseconds = load_le32(&f[24]);
  s.relative_time_us = load_le64(&f[28]);
  return s;
}

Result<std::span<const uint8_t>> decode_poll_payload(std::span<const uint8_t> f) noexcept {
  if (f.size() < kPollPayloadOffset) return FrameError::kPollTruncated;
  const std::size_t size = load_le16(&f[22]);
  if (size > kMaxIsoPayload) return FrameError::kPayloadTooLarge;
  if (kPollPayloadOffset + size > f.size()) return FrameError::kPayloadSizeExceedsFrame;
  return f.subspan(kPollPayloadOffset, size);
}

Result<PReq> decode_preq(std::span<const uint8_t> f, const FrameHeader& h) noexcept {
  if (h.src_node != kNodeMn) return FrameError::kInvalidSourceNode;
  if (!is_cn(h.dst_node)) return FrameError::kInvalidDestinationNode;
  auto payload = decode_poll_payload(f);
  if (!payload) return payload.error();
  PReq p;
  p.multiplexed_slot = (f[18] & kFlagMs) != 0;
  p.exception_acknowledge = (f[18] & kFlagEa) != 0;
  p.ready = (f[18] & kFlagRd) != 0;
  p.pdo_version = f[20];
  p.payload = *payload;
  return p;
}

Result<PRes> decode_pres(std::span<const uint8_t> f, const FrameHeader& h) noexcept {
  if (!is_cn(h.src_node) && h.src_node != kNodeMn) return FrameError::kInvalidSourceNode;
  if (h.dst_node != kNodeBroadcast) return FrameError::kInvalidDestinationNode;
  if (f.size() < kPollPayloadOffset) return FrameError::kPollTruncated;
  if (!is_valid_nmt_state(f[17])) return FrameError::kInvalidNmtState;
  auto payload = decode_poll_payload(f);
  if (!payload) return payload.error();
  PRes p;
  p.nmt_state = static_cast<NmtState>(f[17]);
  p.multiplexed_slot = (f[18] & kFlagMs) != 0;
  p.exception_new = (f[18] & kFlagEn) != 0;
  p.ready = (f[18] & kFlagRd) != 0;
  p.priority = (f[19] >> 3) & 0x07;
  p.request_count = f[19] & 0x07;
  p.pdo_version = f[20];
  p.payload = *payload;
  return p;
}

Result<SoA> decode_soa(std::span<const uint8_t> f, const FrameHeader& h) noexcept {
  if (h.src_node != kNodeMn) return FrameError::kInvalidSourceNode;
  if (h.dst_node != kNodeBroadcast) return FrameError::kInvalidDestinationNode;
  if (f.size() < kSoaSize) return FrameError::kSoaTruncated;
  if (!is_valid_nmt_state(f[17])) return FrameError::kInvalidNmtState;
  if (!is_valid_requested_service(f[20])) return FrameError::kUnknownServiceId;
  SoA s;
  s.mn_nmt_state = static_cast<NmtState>(f[17]);
  s.exception_acknowledge = (f[18] & kFlagEa) != 0;
  s.exception_reset = (f[18] & kFlagEr) != 0;
  s.service = static_cast<RequestedService>(f[20]);
  s.target = f[21];
  s.epl_version = f[22];
  // An invitation must name a node that can answer it.
  if (s.service != RequestedService::kNone && !is_cn(s.target) && s.target != kNodeMn)
    return FrameError::kInvalidDestinationNode;
  return s;
}

Result<IdentResponse> decode_ident(std::span<const uint8_t> f) noexcept {
  if (f.size() < kIdentResponseSize) return FrameError::kIdentResponseTruncated;
  if (!is_valid_nmt_state(f[20])) return FrameError::kInvalidNmtState;
  IdentResponse r;
  r.exception_new = (f[18] & kFlagEn) != 0;
  r.priority = (f[19] >> 3) & 0x07;
  r.request_count = f[19] & 0x07;
  r.nmt_state = static_cast<NmtState>(f[20]);
  r.epl_version = f[22];
  r.feature_flags = load_le32(&f[24]);
  r.mtu = load_le16(&f[28]);
  r.poll_in_size = load_le16(&f[30]);
  r.poll_out_size = load_le16(&f[32]);
  r.response_time_ns = load_le32(&f[34]);
  r.device_type = load_le32(&f[40]);
  r.vendor_id = load_le32(&f[44]);
  r.product_code = load_le32(&f[48]);
  r.revision_no = load_le32(&f[52]);
  r.serial_no = load_le32(&f[56]);
  std::memcpy(r.vendor_ext1.data(), &f[60], 8);
  r.verify_conf_date = load_le32(&f[68]);
  r.verify_conf_time = load_le32(&f[72]);
  r.app_sw_date = load_le32(&f[76]);
  r.app_sw_time = load_le32(&f[80]);
  r.ip_address = load_le32(&f[84]);
  r.subnet_mask = load_le32(&f[88]);
  r.default_gateway = load_le32(&f[92]);
  std::memcpy(r.host_name.data(), &f[96], 32);
  std::memcpy(r.vendor_ext2.data(), &f[128], 48);
  return r;
}

Result<StatusResponse> decode_status(std::span<const uint8_t> f) noexcept {
  // Lenient on the length beyond the static error field: the error list ends at the frame end.
  if (f.size() < kStatusEntryOffset) return FrameError::kStatusResponseTruncated;
  if (!is_valid_nmt_state(f[20])) return FrameError::kInvalidNmtState;
  StatusResponse r;
  r.exception_new = (f[18] & kFlagEn) != 0;
  r.exception_clear = (f[18] & kFlagEc) != 0;
  r.priority = (f[19] >> 3) & 0x07;
  r.request_count = f[19] & 0x07;
  r.nmt_state = static_cast<NmtState>(f[20]);
  r.static_error_bits = load_le64(&f[24]);
  std::size_t n = 0;
  while (kStatusEntryOffset + (n + 1) * kErrorEntrySize <= f.size() &&
         load_le16(&f[kStatusEntryOffset + n * kErrorEntrySize]) != 0)
    ++n;
  r.entries = f.subspan(kStatusEntryOffset, n * kErrorEntrySize);
  return r;
}

Result<Sdo> decode_sdo(std::span<const uint8_t> f) noexcept {
  if (f.size() < kSdoCmdOffset) return FrameError::kSdoTruncated;
  Sdo s;
  s.sequence.recv_seq = f[18] >> 2;
  s.sequence.recv_con = static_cast<SdoRecvCon>(f[18] & 0x03);
  s.sequence.send_seq = f[19] >> 2;
  s.sequence.send_con = static_cast<SdoSendCon>(f[19] & 0x03);
  if (f.size() < kSdoPayloadOffset) {
    // An unpadded sequence-layer-only frame ends at 22 bytes; what there is of a command header
    // must then be the zeros of a Nil command.
    const auto partial = f.subspan(kSdoCmdOffset);
    if (std::any_of(partial.begin(), partial.end(), [](uint8_t b) { return b != 0; }))
      return FrameError::kSdoTruncated;
    return s;
  }
  const uint8_t flags = f[24];
  const uint8_t command_id = f[25];
  const std::size_t segment_size = load_le16(&f[26]);
  s.has_command = !(flags == 0 && command_id == 0 && segment_size == 0);
  if (!s.has_command) return s;
  if (kSdoPayloadOffset + segment_size > f.size()) return FrameError::kSdoSegmentSizeExceedsFrame;
  SdoCommand& c = s.command;
  c.transaction_id = f[23];
  c.response = (flags & kSdoResponse) != 0;
  c.abort = (flags & kSdoAbort) != 0;
  c.segmentation = static_cast<SdoSegmentation>((flags >> 4) & 0x03);
  c.command_id = command_id;
  std::span<const uint8_t> payload = f.subspan(kSdoPayloadOffset, segment_size);
  if (c.abort) {
    if (segment_size < 4) return FrameError::kSdoInconsistentCommand;
  } else if (c.segmentation == SdoSegmentation::kInitiate) {
    if (segment_size < 4) return FrameError::kSdoInconsistentCommand;
    c.total_size = load_le32(payload.data());
    payload = payload.subspan(4);
  }
  c.payload = payload;
  return s;
}

Result<Asnd> decode_asnd(std::span<const uint8_t> f, const FrameHeader& h) noexcept {
  if (h.src_node == kNodeInvalid || h.src_node == kNodeBroadcast)
    return FrameError::kInvalidSourceNode;
  if (h.dst_node == kNodeInvalid) return FrameError::kInvalidDestinationNode;
  if (f.size() < kAsndDataOffset) return FrameError::kAsndTruncated;
  const uint8_t service = f[17];
  Asnd a;
  a.service = static_cast<AsndService>(service);
  switch (a.service) {
    case AsndService::kIdentResponse: {
      auto r = decode_ident(f);
      if (!r) return r.error();
      a.body = *r;
      return a;
    }
    case AsndService::kStatusResponse: {
      auto r = decode_status(f);
      if (!r) return r.error();
      a.body = *r;
      return a;
    }
    case AsndService::kNmtRequest:
      if (f.size() < 20) return FrameError::kAsndTruncated;
      a.body = NmtRequest{f[18], f[19], f.subspan(20)};
      return a;
    case AsndService::kNmtCommand:
      if (h.src_node != kNodeMn) return FrameError::kInvalidSourceNode;
      if (f.size() < 20) return FrameError::kAsndTruncated;
      a.body = NmtCommand{f[18], f.subspan(20)};
      return a;
    case AsndService::kSdo: {
      auto r = decode_sdo(f);
      if (!r) return r.error();
      a.body = *r;
      return a;
    }
    case AsndService::kSyncResponse:
      a.body = AsndRaw{a.service, f.subspan(kAsndDataOffset)};
      return a;
  }
  // Manufacturer-specific services are carried, not interpreted.
  if (service >= 0xA0 && service <= 0xFE) {
    a.body = AsndRaw{a.service, f.subspan(kAsndDataOffset)};
    return a;
  }
  return FrameError::kUnknownServiceId;
}

}  // namespace

bool is_valid_nmt_state(uint8_t raw) noexcept {
  switch (static_cast<NmtState>(raw)) {
    case NmtState::kOff:
    case NmtState::kInitialising:
    case NmtState::kResetApplication:
    case NmtState::kResetCommunication:
    case NmtState::kResetConfiguration:
    case NmtState::kNotActive:
    case NmtState::kPreOperational1:
    case NmtState::kPreOperational2:
    case NmtState::kReadyToOperate:
    case NmtState::kOperational:
    case NmtState::kStopped:
    case NmtState::kBasicEthernet:
      return true;
  }
  return false;
}

std::string_view to_string(NmtState s) noexcept {
  switch (s) {
    case NmtState::kOff:
      return "OFF";
    case NmtState::kInitialising:
      return "INITIALISING";
    case NmtState::kResetApplication:
      return "RESET_APPLICATION";
    case NmtState::kResetCommunication:
      return "RESET_COMMUNICATION";
    case NmtState::kResetConfiguration:
      return "RESET_CONFIGURATION";
    case NmtState::kNotActive:
      return "NOT_ACTIVE";
    case NmtState::kPreOperational1:
      return "PRE_OPERATIONAL_1";
    case NmtState::kPreOperational2:
      return "PRE_OPERATIONAL_2";
    case NmtState::kReadyToOperate:
      return "READY_TO_OPERATE";
    case NmtState::kOperational:
      return "OPERATIONAL";
    case NmtState::kStopped:
      return "STOPPED";
    case NmtState::kBasicEthernet:
      return "BASIC_ETHERNET";
  }
  return "?";
}

std::string_view to_string(MessageType t) noexcept {
  switch (t) {
    case MessageType::kSoC:
      return "SoC";
    case MessageType::kPReq:
      return "PReq";
    case MessageType::kPRes:
      return "PRes";
    case MessageType::kSoA:
      return "SoA";
    case MessageType::kASnd:
      return "ASnd";
  }
  return "frame";
}

std::string_view to_string(NmtCommandId c) noexcept {
  switch (c) {
    case NmtCommandId::kStartNode:
      return "NMTStartNode";
    case NmtCommandId::kStopNode:
      return "NMTStopNode";
    case NmtCommandId::kEnterPreOperational2:
      return "NMTEnterPreOperational2";
    case NmtCommandId::kEnableReadyToOperate:
      return "NMTEnableReadyToOperate";
    case NmtCommandId::kResetNode:
      return "NMTResetNode";
    case NmtCommandId::kResetCommunication:
      return "NMTResetCommunication";
    case NmtCommandId::kResetConfiguration:
      return "NMTResetConfiguration";
    case NmtCommandId::kSwReset:
      return "NMTSwReset";
  }
  return "?";
}

ErrorEntry StatusResponse::entry(std::size_t i) const noexcept {
  const uint8_t* p = entries.data() + i * kErrorEntrySize;
  ErrorEntry e;
  e.type = load_le16(p);
  e.code = load_le16(p + 2);
  e.timestamp = load_le64(p + 4);
  std::memcpy(e.additional.data(), p + 12, 8);
  return e;
}

// ---- Build --------------------------------------------------------------------------------------

Result<std::size_t> build_soc(std::span<uint8_t> out, const FrameHeader& h,
                              const Soc& soc) noexcept {
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, 36, h, MessageType::kSoC, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[18] = static_cast<uint8_t>((soc.multiplexed_cycle_completed ? kFlagMc : 0) |
                               (soc.prescaled_slot ? kFlagPs : 0));
  store_le32(p + 20, soc.net_time.seconds);
  store_le32(p + 24, soc.net_time.nanoseconds);
  store_le64(p + 28, soc.relative_time_us);
  return len;
}

Result<std::size_t> build_preq(std::span<uint8_t> out, const FrameHeader& h,
                               const PReq& preq) noexcept {
  if (preq.payload.size() > kMaxIsoPayload) return FrameError::kPayloadTooLarge;
  std::size_t len = 0;
  uint8_t* p =
      begin_frame(out, kPollPayloadOffset + preq.payload.size(), h, MessageType::kPReq, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[18] =
      static_cast<uint8_t>((preq.multiplexed_slot ? kFlagMs : 0) |
                           (preq.exception_acknowledge ? kFlagEa : 0) | (preq.ready ? kFlagRd : 0));
  p[20] = preq.pdo_version;
  store_le16(p + 22, static_cast<uint16_t>(preq.payload.size()));
  if (!preq.payload.empty())
    std::memcpy(p + kPollPayloadOffset, preq.payload.data(), preq.payload.size());
  return len;
}

Result<std::size_t> build_pres(std::span<uint8_t> out, const FrameHeader& h,
                               const PRes& pres) noexcept {
  if (pres.payload.size() > kMaxIsoPayload) return FrameError::kPayloadTooLarge;
  std::size_t len = 0;
  uint8_t* p =
      begin_frame(out, kPollPayloadOffset + pres.payload.size(), h, MessageType::kPRes, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(pres.nmt_state);
  p[18] = static_cast<uint8_t>((pres.multiplexed_slot ? kFlagMs : 0) |
                               (pres.exception_new ? kFlagEn : 0) | (pres.ready ? kFlagRd : 0));
  p[19] = pr_rs(pres.priority, pres.request_count);
  p[20] = pres.pdo_version;
  store_le16(p + 22, static_cast<uint16_t>(pres.payload.size()));
  if (!pres.payload.empty())
    std::memcpy(p + kPollPayloadOffset, pres.payload.data(), pres.payload.size());
  return len;
}

Result<std::size_t> build_soa(std::span<uint8_t> out, const FrameHeader& h,
                              const SoA& soa) noexcept {
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, 23, h, MessageType::kSoA, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(soa.mn_nmt_state);
  p[18] = static_cast<uint8_t>((soa.exception_acknowledge ? kFlagEa : 0) |
                               (soa.exception_reset ? kFlagEr : 0));
  p[20] = static_cast<uint8_t>(soa.service);
  p[21] = soa.target;
  p[22] = soa.epl_version;
  return len;
}

Result<std::size_t> build_ident_response(std::span<uint8_t> out, const FrameHeader& h,
                                         const IdentResponse& r) noexcept {
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, kIdentResponseSize, h, MessageType::kASnd, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(AsndService::kIdentResponse);
  p[18] = r.exception_new ? kFlagEn : 0;
  p[19] = pr_rs(r.priority, r.request_count);
  p[20] = static_cast<uint8_t>(r.nmt_state);
  p[22] = r.epl_version;
  store_le32(p + 24, r.feature_flags);
  store_le16(p + 28, r.mtu);
  store_le16(p + 30, r.poll_in_size);
  store_le16(p + 32, r.poll_out_size);
  store_le32(p + 34, r.response_time_ns);
  store_le32(p + 40, r.device_type);
  store_le32(p + 44, r.vendor_id);
  store_le32(p + 48, r.product_code);
  store_le32(p + 52, r.revision_no);
  store_le32(p + 56, r.serial_no);
  std::memcpy(p + 60, r.vendor_ext1.data(), 8);
  store_le32(p + 68, r.verify_conf_date);
  store_le32(p + 72, r.verify_conf_time);
  store_le32(p + 76, r.app_sw_date);
  store_le32(p + 80, r.app_sw_time);
  store_le32(p + 84, r.ip_address);
  store_le32(p + 88, r.subnet_mask);
  store_le32(p + 92, r.default_gateway);
  std::memcpy(p + 96, r.host_name.data(), 32);
  std::memcpy(p + 128, r.vendor_ext2.data(), 48);
  return len;
}

Result<std::size_t> build_status_response(std::span<uint8_t> out, const FrameHeader& h,
                                          const StatusResponse& r,
                                          std::span<const ErrorEntry> entries) noexcept {
  const std::size_t content =
      std::max(kStatusResponseMinSize, kStatusEntryOffset + (entries.size() + 1) * kErrorEntrySize);
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, content, h, MessageType::kASnd, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(AsndService::kStatusResponse);
  p[18] = static_cast<uint8_t>((r.exception_new ? kFlagEn : 0) | (r.exception_clear ? kFlagEc : 0));
  p[19] = pr_rs(r.priority, r.request_count);
  p[20] = static_cast<uint8_t>(r.nmt_state);
  store_le64(p + 24, r.static_error_bits);
  uint8_t* e = p + kStatusEntryOffset;
  for (const ErrorEntry& entry : entries) {
    store_le16(e, entry.type);
    store_le16(e + 2, entry.code);
    store_le64(e + 4, entry.timestamp);
    std::memcpy(e + 12, entry.additional.data(), 8);
    e += kErrorEntrySize;
  }
  return len;  // the terminating entry is the zeroed bytes after the last one
}

Result<std::size_t> build_nmt_command(std::span<uint8_t> out, const FrameHeader& h,
                                      const NmtCommand& c) noexcept {
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, 20 + c.data.size(), h, MessageType::kASnd, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(AsndService::kNmtCommand);
  p[18] = c.command;
  if (!c.data.empty()) std::memcpy(p + 20, c.data.data(), c.data.size());
  return len;
}

Result<std::size_t> build_nmt_request(std::span<uint8_t> out, const FrameHeader& h,
                                      const NmtRequest& r) noexcept {
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, 20 + r.data.size(), h, MessageType::kASnd, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(AsndService::kNmtRequest);
  p[18] = r.command;
  p[19] = r.target;
  if (!r.data.empty()) std::memcpy(p + 20, r.data.data(), r.data.size());
  return len;
}

Result<std::size_t> build_sdo(std::span<uint8_t> out, const FrameHeader& h, const Sdo& s) noexcept {
  const SdoCommand& c = s.command;
  const bool initiate = s.has_command && !c.abort && c.segmentation == SdoSegmentation::kInitiate;
  const std::size_t segment_size = s.has_command ? c.payload.size() + (initiate ? 4 : 0) : 0;
  if (segment_size > kMaxSdoSegment) return FrameError::kPayloadTooLarge;
  std::size_t len = 0;
  uint8_t* p = begin_frame(out, kSdoPayloadOffset + segment_size, h, MessageType::kASnd, len);
  if (!p) return FrameError::kBufferTooSmall;
  p[17] = static_cast<uint8_t>(AsndService::kSdo);
  p[18] =
      static_cast<uint8_t>((s.sequence.recv_seq << 2) | static_cast<uint8_t>(s.sequence.recv_con));
  p[19] =
      static_cast<uint8_t>((s.sequence.send_seq << 2) | static_cast<uint8_t>(s.sequence.send_con));
  if (!s.has_command) return len;
  p[23] = c.transaction_id;
  p[24] = static_cast<uint8_t>((c.response ? kSdoResponse : 0) | (c.abort ? kSdoAbort : 0) |
                               (static_cast<uint8_t>(c.segmentation) << 4));
  p[25] = c.command_id;
  store_le16(p + 26, static_cast<uint16_t>(segment_size));
  uint8_t* d = p + kSdoPayloadOffset;
  if (initiate) {
    store_le32(d, c.total_size);
    d += 4;
  }
  if (!c.payload.empty()) std::memcpy(d, c.payload.data(), c.payload.size());
  return len;
}

FrameHeader soc_header(const MacAddress& src_mac) noexcept {
  return {kMacSoc, src_mac, MessageType::kSoC, kNodeBroadcast, kNodeMn};
}
FrameHeader soa_header(const MacAddress& src_mac) noexcept {
  return {kMacSoA, src_mac, MessageType::kSoA, kNodeBroadcast, kNodeMn};
}
FrameHeader preq_header(const MacAddress& src_mac, const MacAddress& dst_mac,
                        uint8_t cn_node) noexcept {
  return {dst_mac, src_mac, MessageType::kPReq, cn_node, kNodeMn};
}
FrameHeader pres_header(const MacAddress& src_mac, uint8_t cn_node) noexcept {
  return {kMacPRes, src_mac, MessageType::kPRes, kNodeBroadcast, cn_node};
}
FrameHeader asnd_header(const MacAddress& src_mac, uint8_t src_node, uint8_t dst_node) noexcept {
  return {kMacAsnd, src_mac, MessageType::kASnd, dst_node, src_node};
}

// ---- Parse --------------------------------------------------------------------------------------

Result<FrameHeader> parse_header(std::span<const uint8_t> f) noexcept {
  if (f.size() < kHeaderSize) return FrameError::kFrameTooShort;
  if (f.size() > kMaxFrameSize) return FrameError::kFrameTooLong;
  if (((f[12] << 8) | f[13]) != kEtherType) return FrameError::kNotPowerlink;
  const uint8_t type = f[kTypeOffset] & 0x7F;
  switch (static_cast<MessageType>(type)) {
    case MessageType::kSoC:
    case MessageType::kPReq:
    case MessageType::kPRes:
    case MessageType::kSoA:
    case MessageType::kASnd:
      break;
    default:
      return FrameError::kUnknownMessageType;
  }
  FrameHeader h;
  std::memcpy(h.dst_mac.data(), f.data(), 6);
  std::memcpy(h.src_mac.data(), f.data() + 6, 6);
  h.type = static_cast<MessageType>(type);
  h.dst_node = f[kDstNodeOffset];
  h.src_node = f[kSrcNodeOffset];
  return h;
}

Result<Frame> parse_frame(std::span<const uint8_t> f) noexcept {
  auto h = parse_header(f);
  if (!h) return h.error();
  Frame frame;
  frame.header = *h;
  auto take = [&](auto r) -> std::error_code {
    if (!r) return r.error();
    frame.message = *r;
    return {};
  };
  std::error_code ec;
  switch (h->type) {
    case MessageType::kSoC:
      ec = take(decode_soc(f, *h));
      break;
    case MessageType::kPReq:
      ec = take(decode_preq(f, *h));
      break;
    case MessageType::kPRes:
      ec = take(decode_pres(f, *h));
      break;
    case MessageType::kSoA:
      ec = take(decode_soa(f, *h));
      break;
    case MessageType::kASnd:
      ec = take(decode_asnd(f, *h));
      break;
  }
  if (ec) return ec;
  return frame;
}

namespace {
template <class T>
Result<T> parse_as(std::span<const uint8_t> f) noexcept {
  auto r = parse_frame(f);
  if (!r) return r.error();
  if (const T* m = std::get_if<T>(&r->message)) return *m;
  return FrameError::kWrongMessageType;
}
}  // namespace

Result<Soc> parse_soc(std::span<const uint8_t> f) noexcept {
  return parse_as<Soc>(f);
}
Result<PReq> parse_preq(std::span<const uint8_t> f) noexcept {
  return parse_as<PReq>(f);
}
Result<PRes> parse_pres(std::span<const uint8_t> f) noexcept {
  return parse_as<PRes>(f);
}
Result<SoA> parse_soa(std::span<const uint8_t> f) noexcept {
  return parse_as<SoA>(f);
}
Result<Asnd> parse_asnd(std::span<const uint8_t> f) noexcept {
  return parse_as<Asnd>(f);
}

}  // namespace ds1928::powerlink
