#include "canio/sdo_expedited.hpp"

#include <string>

namespace ds1928::canio {
namespace {

// Command specifier bits 7..5 of byte 0.
constexpr uint8_t kCcsDownload = 1;  // client: initiate download
constexpr uint8_t kCcsUpload = 2;    // client: initiate upload
constexpr uint8_t kScsUpload = 2;    // server: initiate upload response
constexpr uint8_t kScsDownload = 3;  // server: initiate download response
constexpr uint8_t kCsAbort = 4;      // either side
constexpr uint8_t kExpedited = 0x02;
constexpr uint8_t kSizeIndicated = 0x01;

constexpr bool valid_node(uint8_t node) noexcept {
  return node >= 1 && node <= 127;
}

uint8_t expedited_specifier(uint8_t cs, uint8_t size) noexcept {
  return static_cast<uint8_t>((cs << 5) | ((4 - size) << 2) | kExpedited | kSizeIndicated);
}

CanFrame sdo_frame(uint32_t cob_id, uint8_t specifier, const SdoMessage& m,
                   uint32_t payload) noexcept {
  CanFrame f;
  f.id = cob_id;
  f.dlc = 8;
  f.data[0] = specifier;
  f.data[1] = static_cast<uint8_t>(m.index & 0xFF);
  f.data[2] = static_cast<uint8_t>(m.index >> 8);
  f.data[3] = m.subindex;
  for (int i = 0; i < 4; ++i) f.data[4 + i] = static_cast<uint8_t>(payload >> (8 * i));
  return f;
}

uint32_t masked(uint32_t value, uint8_t size) noexcept {
  return size >= 4 ? value : value & ((1u << (8 * size)) - 1u);
}

Result<CanFrame> build(uint8_t node, bool from_server, const SdoMessage& m) noexcept {
  if (!valid_node(node)) return SdoFrameError::kInvalidNode;
  const uint32_t cob = (from_server ? kSdoResponseBase : kSdoRequestBase) + node;
  switch (m.command) {
    case SdoCommand::DownloadRequest:
    case SdoCommand::UploadResponse: {
      if ((m.command == SdoCommand::DownloadRequest) == from_server)
        return SdoFrameError::kCommandMismatch;
      if (m.size < 1 || m.size > 4) return SdoFrameError::kInvalidSize;
      const uint8_t cs = m.command == SdoCommand::DownloadRequest ? kCcsDownload : kScsUpload;
      // "Size not indicated" (e = 1, s = 0, n = 0): the 4 data bytes go out as they are.
      const uint8_t spec = m.size_indicated ? expedited_specifier(cs, m.size)
                                            : static_cast<uint8_t>((cs << 5) | kExpedited);
      return sdo_frame(cob, spec, m, masked(m.value, m.size));
    }
    case SdoCommand::UploadRequest:
      if (from_server) return SdoFrameError::kCommandMismatch;
      return sdo_frame(cob, kCcsUpload << 5, m, 0);
    case SdoCommand::DownloadResponse:
      if (!from_server) return SdoFrameError::kCommandMismatch;
      return sdo_frame(cob, kScsDownload << 5, m, 0);
    case SdoCommand::Abort:
      return sdo_frame(cob, kCsAbort << 5, m, m.value);
  }
  return SdoFrameError::kUnknownCommand;
}

class SdoFrameCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "canopen.sdo"; }
  std::string message(int ev) const override {
    switch (static_cast<SdoFrameError>(ev)) {
      case SdoFrameError::kInvalidNode:
        return "CANopen node id outside 1..127";
      case SdoFrameError::kInvalidSize:
        return "expedited SDO data size outside 1..4 bytes";
      case SdoFrameError::kWrongCobId:
        return "SDO frame on another COB-ID than 0x600/0x580 + node";
      case SdoFrameError::kWrongLength:
        return "SDO frame with a data length other than 8";
      case SdoFrameError::kRemoteOrErrorFrame:
        return "remote or error frame on an SDO identifier";
      case SdoFrameError::kUnknownCommand:
        return "SDO command specifier not defined for this direction";
      case SdoFrameError::kSegmentedNotSupported:
        return "SDO response starts a segmented transfer; only expedited (1..4 bytes) is supported";
      case SdoFrameError::kCommandMismatch:
        return "SDO response does not answer the request (upload vs download)";
      case SdoFrameError::kIndexMismatch:
        return "SDO response names another index than the request";
      case SdoFrameError::kSubindexMismatch:
        return "SDO response names another subindex than the request";
      case SdoFrameError::kSizeMismatch:
        return "SDO upload response carries another data size than the register has";
    }
    return "unknown SDO frame error " + std::to_string(ev);
  }
};

}  // namespace

const std::error_category& sdo_frame_category() noexcept {
  static const SdoFrameCategory category;
  return category;
}

Result<CanFrame> build_sdo_request(uint8_t node, const SdoMessage& message) noexcept {
  return build(node, false, message);
}

Result<CanFrame> build_sdo_response(uint8_t node, const SdoMessage& message) noexcept {
  return build(node, true, message);
}

Result<SdoMessage> parse_sdo(uint8_t node, bool from_server, const CanFrame& f) noexcept {
  if (!valid_node(node)) return SdoFrameError::kInvalidNode;
  const uint32_t cob = (from_server ? kSdoResponseBase : kSdoRequestBase) + node;
  if (f.extended || f.id != cob) return SdoFrameError::kWrongCobId;
  if (f.rtr || f.error) return SdoFrameError::kRemoteOrErrorFrame;
  // CiA 301 requires all 8 bytes in every SDO frame; a shorter one is malformed.
  if (f.dlc != 8) return SdoFrameError::kWrongLength;
  SdoMessage m;
  const uint8_t spec = f.data[0];
  m.index = static_cast<uint16_t>(f.data[1] | (f.data[2] << 8));
  m.subindex = f.data[3];
  const uint32_t payload = static_cast<uint32_t>(f.data[4]) | (uint32_t{f.data[5]} << 8) |
                           (uint32_t{f.data[6]} << 16) | (uint32_t{f.data[7]} << 24);
  const uint8_t cs = spec >> 5;
  if (cs == kCsAbort) {
    m.command = SdoCommand::Abort;
    m.value = payload;
    return m;
  }
  const bool expedited = (spec & kExpedited) != 0;
  const bool size_indicated = (spec & kSizeIndicated) != 0;
  // Expedited with size not indicated: the data size is unspecified, CiA 301 says up to 4 bytes.
  const uint8_t size =
      expedited ? (size_indicated ? static_cast<uint8_t>(4 - ((spec >> 2) & 0x3)) : 4) : 0;
  if (!from_server) {
    if (cs == kCcsDownload) {
      if (!expedited) return SdoFrameError::kSegmentedNotSupported;
      m.command = SdoCommand::DownloadRequest;
      m.size = size;
      m.size_indicated = size_indicated;
      m.value = masked(payload, size);
      return m;
    }
    if (cs == kCcsUpload) {
      m.command = SdoCommand::UploadRequest;
      return m;
    }
    return SdoFrameError::kUnknownCommand;
  }
  if (cs == kScsDownload) {
    m.command = SdoCommand::DownloadResponse;
    return m;
  }
  if (cs == kScsUpload) {
    if (!expedited) return SdoFrameError::kSegmentedNotSupported;
    m.command = SdoCommand::UploadResponse;
    m.size = size;
    m.size_indicated = size_indicated;
    m.value = masked(payload, size);
    return m;
  }
  return SdoFrameError::kUnknownCommand;
}

Result<SdoMessage> match_sdo_response(uint8_t node, const SdoMessage& request,
                                      const CanFrame& response, uint8_t expected_size) noexcept {
  auto parsed = parse_sdo(node, true, response);
  if (!parsed) return parsed.error();
  SdoMessage& r = parsed.value();
  if (r.command == SdoCommand::UploadResponse && !r.size_indicated && expected_size != 0) {
    // "Size not indicated": the server leaves the size open; the register's size says it.
    r.size = expected_size;
    r.value = masked(r.value, expected_size);
  }
  // An abort names the object it refers to; one for another object is not this transfer's answer.
  if (r.index != request.index) return SdoFrameError::kIndexMismatch;
  if (r.subindex != request.subindex) return SdoFrameError::kSubindexMismatch;
  if (r.command == SdoCommand::Abort) return make_sdo_abort_error(r.value);
  switch (request.command) {
    case SdoCommand::DownloadRequest:
      if (r.command != SdoCommand::DownloadResponse) return SdoFrameError::kCommandMismatch;
      return r;
    case SdoCommand::UploadRequest:
      if (r.command != SdoCommand::UploadResponse) return SdoFrameError::kCommandMismatch;
      if (expected_size != 0 && r.size != expected_size) return SdoFrameError::kSizeMismatch;
      return r;
    default:
      return SdoFrameError::kCommandMismatch;  // only requests have responses
  }
}

}  // namespace ds1928::canio
