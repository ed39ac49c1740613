#include "powerlink/errors.hpp"

namespace ds1928::powerlink {
namespace {

class FrameCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "powerlink.frame"; }
  std::string message(int ev) const override {
    switch (static_cast<FrameError>(ev)) {
      case FrameError::kFrameTooShort:
        return "frame shorter than the 17-byte POWERLINK header";
      case FrameError::kFrameTooLong:
        return "frame longer than 1514 bytes";
      case FrameError::kNotPowerlink:
        return "EtherType is not 0x88AB";
      case FrameError::kUnknownMessageType:
        return "unknown POWERLINK message type";
      case FrameError::kPayloadSizeExceedsFrame:
        return "payload size runs past the frame end";
      case FrameError::kPayloadTooLarge:
        return "isochronous payload above 1490 bytes";
      case FrameError::kInvalidSourceNode:
        return "source node id invalid for this message";
      case FrameError::kInvalidDestinationNode:
        return "destination node id invalid for this message";
      case FrameError::kInvalidNmtState:
        return "undefined NMT state";
      case FrameError::kUnknownServiceId:
        return "unknown service id";
      case FrameError::kSdoSegmentSizeExceedsFrame:
        return "SDO segment size runs past the frame end";
      case FrameError::kSdoInconsistentCommand:
        return "inconsistent SDO command layer";
      case FrameError::kWrongMessageType:
        return "frame is of another message type";
      case FrameError::kBufferTooSmall:
        return "buffer too small for the frame";
      case FrameError::kSocTruncated:
        return "SoC truncated: its fields need 36 bytes";
      case FrameError::kPollTruncated:
        return "PReq/PRes truncated: its header needs 24 bytes";
      case FrameError::kSoaTruncated:
        return "SoA truncated: its fields need 23 bytes";
      case FrameError::kAsndTruncated:
        return "ASnd truncated: ServiceID missing, or NMTCommand/NMTRequest shorter than 20 bytes";
      case FrameError::kIdentResponseTruncated:
        return "IdentResponse truncated: it needs 176 bytes";
      case FrameError::kStatusResponseTruncated:
        return "StatusResponse truncated: it needs 32 bytes up to its static error field";
      case FrameError::kSdoTruncated:
        return "SDO truncated: sequence layer missing or command layer header incomplete";
      case FrameError::kSyncRequestTruncated:
        return "SyncRequest truncated: its fields need 54 bytes (to DestMacAddress)";
      case FrameError::kSyncResponseTruncated:
        return "SyncResponse truncated: its fields need 44 bytes (to PResTimeSecond)";
    }
    return "unknown frame error";
  }
};

class SdoCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "powerlink.sdo"; }
  std::string message(int ev) const override {
    switch (static_cast<SdoError>(ev)) {
      case SdoError::kBusy:
        return "SDO transfer already in progress for this node";
      case SdoError::kTimeout:
        return "SDO timeout";
      case SdoError::kProtocol:
        return "SDO protocol error";
      case SdoError::kConnectionLost:
        return "SDO connection lost";
      case SdoError::kDataTooLarge:
        return "SDO data too large";
      case SdoError::kNoMapping:
        return "register has no SDO object mapping";
    }
    return "unknown SDO error";
  }
};

class MnCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "powerlink.mn"; }
  std::string message(int ev) const override {
    switch (static_cast<MnError>(ev)) {
      case MnError::kIdentMismatch:
        return "IdentResponse does not match the configured identity";
      case MnError::kPresSizeMismatch:
        return "PRes payload size differs from the expected size";
      case MnError::kNodeNotConfigured:
        return "node not configured";
      case MnError::kNodeNotOperational:
        return "node not operational";
      case MnError::kQueueFull:
        return "request queue full";
      case MnError::kLinkDown:
        return "link down";
      case MnError::kInvalidLayout:
        return "invalid process image layout";
      case MnError::kPreqRegionOwnedByModule:
        return "PReq bytes belong to an X20DS1928 module";
      case MnError::kPreqOutOfRange:
        return "PReq write runs past the PReq payload";
      case MnError::kPreqWriteTooLong:
        return "PReq write too long for one request";
      case MnError::kModuleBlocksOverlap:
        return "two modules' process data blocks overlap";
      case MnError::kModuleBlockOutsidePayload:
        return "module's process data block runs past the PRes/PReq payload";
      case MnError::kLossOfPresThreshold:
        return "loss of PRes threshold reached";
      case MnError::kBootStepTimeout:
        return "boot step timed out";
      case MnError::kResetRequested:
        return "reset requested by the node (NMTRequest)";
      case MnError::kNmtRequestRefused:
        return "NMTRequest refused (only a node's own reset is served)";
      case MnError::kIdentityCheckFailed:
        return "identity check failed (device type or identity object differs from the "
               "configuration or cannot be read)";
      case MnError::kPrcNotSupported:
        return "node does not support PollResponse Chaining (no PRC feature flag): polled with "
               "PReq/PRes";
      case MnError::kPrcSyncFailed:
        return "PollResponse Chaining set-up failed (no or wrong SyncResponse)";
      case MnError::kConfigurationNotVerified:
        return "configuration not verified: after NMTResetConfiguration the node reports another "
               "configuration date/time (CFM_VerifyConfiguration) than expected "
               "(CFM_ExpConfDateList/TimeList); written again";
      case MnError::kPdoMappingEntryInvalid:
        return "PDO mapping entry with an unusable length or offset";
      case MnError::kPdoRegisterNotMapped:
        return "PDO mapping lacks a register the axis needs";
    }
    return "unknown MN error";
  }
};

}  // namespace

const std::error_category& frame_category() noexcept {
  static const FrameCategory c;
  return c;
}
const std::error_category& sdo_category() noexcept {
  static const SdoCategory c;
  return c;
}
const std::error_category& mn_category() noexcept {
  static const MnCategory c;
  return c;
}

uint32_t to_sdo_abort_code(std::error_code ec) noexcept {
  if (const auto code = sdo_abort_code(ec)) return *code;
  if (ec == SdoError::kTimeout) return sdo_abort::kTimeout;
  if (ec == SdoError::kDataTooLarge) return sdo_abort::kOutOfMemory;
  return sdo_abort::kGeneral;
}

}  // namespace ds1928::powerlink
