#include "canio/sdo_client.hpp"

namespace ds1928::canio {

Result<CanFrame> ExpeditedSdoClient::start(uint8_t node, const SdoMessage& request,
                                           uint8_t expected_size, int64_t now_ns) noexcept {
  if (busy_) return std::make_error_code(std::errc::operation_in_progress);
  auto frame = build_sdo_request(node, request);
  if (!frame) return frame.error();
  busy_ = true;
  node_ = node;
  request_ = request;
  expected_size_ = expected_size;
  deadline_ns_ = now_ns + timeout_ns_;
  return frame;
}

Result<CanFrame> ExpeditedSdoClient::read(uint8_t node, uint16_t index, uint8_t subindex,
                                          uint8_t expected_size, int64_t now_ns) noexcept {
  SdoMessage m;
  m.command = SdoCommand::UploadRequest;
  m.index = index;
  m.subindex = subindex;
  return start(node, m, expected_size, now_ns);
}

Result<CanFrame> ExpeditedSdoClient::write(uint8_t node, uint16_t index, uint8_t subindex,
                                           uint8_t size, uint32_t value, int64_t now_ns) noexcept {
  SdoMessage m;
  m.command = SdoCommand::DownloadRequest;
  m.index = index;
  m.subindex = subindex;
  m.size = size;
  m.value = value;
  return start(node, m, 0, now_ns);
}

std::optional<SdoOutcome> ExpeditedSdoClient::receive(const CanFrame& f) noexcept {
  if (!busy_ || f.error || f.rtr || f.extended || f.id != kSdoResponseBase + node_)
    return std::nullopt;
  // The server's one answer ends the transfer, whatever it says: any size is taken here so that
  // a read of another size still reports what was answered.
  busy_ = false;
  SdoOutcome out;
  auto m = match_sdo_response(node_, request_, f,
                              request_.command == SdoCommand::UploadRequest ? expected_size_ : 0);
  if (!m && m.error() == SdoFrameError::kSizeMismatch) {
    // Another indicated size: reported with what was answered (the caller names it).
    auto any = match_sdo_response(node_, request_, f, 0);
    if (any) {
      out.value = any->value;
      out.size = any->size;
    }
    out.error = m.error();
    return out;
  }
  if (!m) {
    out.error = m.error();
    return out;
  }
  out.value = m->value;
  out.size = m->size;
  if (request_.command == SdoCommand::UploadRequest && expected_size_ != 0 &&
      m->size != expected_size_)
    out.error = make_error_code(SdoFrameError::kSizeMismatch);
  return out;
}

std::optional<SdoOutcome> ExpeditedSdoClient::tick(int64_t now_ns) noexcept {
  if (!busy_ || now_ns < deadline_ns_) return std::nullopt;
  busy_ = false;
  SdoOutcome out;
  out.timed_out = true;
  return out;
}

}  // namespace ds1928::canio
