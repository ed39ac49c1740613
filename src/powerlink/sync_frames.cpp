#include "powerlink/sync_frames.hpp"

#include <cstring>

namespace ds1928::powerlink {

Result<std::size_t> build_sync_request(std::span<uint8_t> out, const FrameHeader& header,
                                       const SyncRequest& req) noexcept {
  SoA soa;
  soa.mn_nmt_state = req.mn_nmt_state;
  soa.exception_acknowledge = req.exception_acknowledge;
  soa.exception_reset = req.exception_reset;
  soa.service = RequestedService::kSyncRequest;
  soa.target = req.target;
  auto len = build_soa(out, header, soa);
  if (!len) return len;
  // build_soa() pads to 60 bytes: the payload (to byte 54) fits in the padding.
  uint8_t* p = out.data();
  store_le32(p + 24, req.sync_control);
  store_le32(p + 28, req.pres_time_first_ns);
  store_le32(p + 32, req.pres_time_second_ns);
  store_le32(p + 36, req.sync_mn_delay_first_ns);
  store_le32(p + 40, req.sync_mn_delay_second_ns);
  store_le32(p + 44, req.pres_fallback_timeout_ns);
  std::memcpy(p + 48, req.dest_mac.data(), req.dest_mac.size());
  return len;
}

Result<SyncRequest> parse_sync_request(std::span<const uint8_t> frame) noexcept {
  auto soa = parse_soa(frame);
  if (!soa) return soa.error();
  if (soa->service != RequestedService::kSyncRequest) return FrameError::kWrongMessageType;
  if (frame.size() < kSyncRequestSize) return FrameError::kSyncRequestTruncated;
  const uint8_t* p = frame.data();
  SyncRequest r;
  r.mn_nmt_state = soa->mn_nmt_state;
  r.exception_acknowledge = soa->exception_acknowledge;
  r.exception_reset = soa->exception_reset;
  r.target = soa->target;
  r.sync_control = load_le32(p + 24);
  r.pres_time_first_ns = load_le32(p + 28);
  r.pres_time_second_ns = load_le32(p + 32);
  r.sync_mn_delay_first_ns = load_le32(p + 36);
  r.sync_mn_delay_second_ns = load_le32(p + 40);
  r.pres_fallback_timeout_ns = load_le32(p + 44);
  std::memcpy(r.dest_mac.data(), p + 48, r.dest_mac.size());
  return r;
}

Result<std::size_t> build_sync_response(std::span<uint8_t> out, const FrameHeader& header,
                                        const SyncResponse& res) noexcept {
  // The ASnd header and the service id, then the fields; padded to 60 bytes like every builder.
  if (out.size() < kMinFrameSize) return FrameError::kBufferTooSmall;
  NmtCommand dummy;  // build the common ASnd frame start with an empty NMT command, then overwrite
  auto len = build_nmt_command(out, header, dummy);
  if (!len) return len;
  uint8_t* p = out.data();
  std::memset(p + kAsndDataOffset, 0, *len - kAsndDataOffset);
  p[17] = static_cast<uint8_t>(AsndService::kSyncResponse);
  store_le32(p + 20, res.sync_status);
  store_le32(p + 24, res.latency_ns);
  store_le32(p + 28, res.sync_node_number);
  store_le32(p + 32, res.sync_delay_ns);
  store_le32(p + 36, res.pres_time_first_ns);
  store_le32(p + 40, res.pres_time_second_ns);
  return len;
}

Result<SyncResponse> parse_sync_response(std::span<const uint8_t> data) noexcept {
  if (data.size() < kSyncResponseSize - kAsndDataOffset) return FrameError::kSyncResponseTruncated;
  const uint8_t* p = data.data() - kAsndDataOffset;  // offsets below count from the frame start
  SyncResponse r;
  r.sync_status = load_le32(p + 20);
  r.latency_ns = load_le32(p + 24);
  r.sync_node_number = load_le32(p + 28);
  r.sync_delay_ns = load_le32(p + 32);
  r.pres_time_first_ns = load_le32(p + 36);
  r.pres_time_second_ns = load_le32(p + 40);
  return r;
}

}  // namespace ds1928::powerlink
