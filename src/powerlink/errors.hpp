// Error codes of the POWERLINK layer (own std::error_category, Lely style): parse and build calls
// return a Result (core/result.hpp), a value or a named error, never throw.
#pragma once

#include <cstdint>
#include <system_error>
#include <type_traits>

#include "core/result.hpp"
#include "core/sdo_abort.hpp"

namespace ds1928::powerlink {

// What was wrong with a frame (parse) or a request to build one.
enum class FrameError : int {
  kFrameTooShort = 1,           // shorter than the 17-byte POWERLINK header (or the Ethernet one)
  kFrameTooLong,                // more than 1514 bytes
  kNotPowerlink,                // EtherType is not 0x88AB
  kUnknownMessageType,          // MessageType not SoC/PReq/PRes/SoA/ASnd
  kPayloadSizeExceedsFrame,     // PReq/PRes payload size runs past the frame end
  kPayloadTooLarge,             // isochronous payload above 1490 bytes
  kInvalidSourceNode,           // source node id impossible for this message type
  kInvalidDestinationNode,      // destination node id impossible for this message type
  kInvalidNmtState,             // NMT state byte is not a defined state
  kUnknownServiceId,            // ASnd ServiceID or SoA RequestedServiceID not defined
  kSdoSegmentSizeExceedsFrame,  // SDO command segment size runs past the frame end
  kSdoInconsistentCommand,      // e.g. an abort without its 4-byte code, initiate without size
  kWrongMessageType,            // a parse_xxx() call got a frame of another type
  kBufferTooSmall,              // build: output span cannot hold the frame
  // The frame ends inside the fixed fields of its message. Frames shorter than Ethernet's 60
  // bytes are otherwise accepted: software senders on veth/TAP links do not pad.
  kSocTruncated,             // SoC shorter than 36 bytes
  kPollTruncated,            // PReq/PRes shorter than 24 bytes (header up to the payload size)
  kSoaTruncated,             // SoA shorter than 23 bytes
  kAsndTruncated,            // ASnd without its ServiceID, or NMTCommand/NMTRequest < 20 bytes
  kIdentResponseTruncated,   // IdentResponse shorter than 176 bytes
  kStatusResponseTruncated,  // StatusResponse shorter than 32 bytes (up to the static error field)
  kSdoTruncated,             // SDO without its sequence layer, or a partial command header
  kSyncRequestTruncated,     // SyncRequest (SoA, service 6) shorter than 54 bytes (to DestMac)
  kSyncResponseTruncated,    // SyncResponse shorter than 44 bytes (to PResTimeSecond)
};

// SDO transfer outcome not expressed by an abort code from the peer.
enum class SdoError : int {
  kBusy = 1,        // the node already has a transfer in progress
  kTimeout,         // no answer within the SDO timeout
  kProtocol,        // unexpected frame in the transfer (sequence, transaction, size)
  kConnectionLost,  // the node left the network (loss, reset) during the transfer
  kDataTooLarge,    // the value does not fit the caller's buffer / the transfer limit
  kNoMapping,       // register has no (index, subindex)
};

// NMT / MN conditions reported in status and results.
enum class MnError : int {
  kIdentMismatch = 1,   // IdentResponse vendor/product/device type differs from the configuration
  kPresSizeMismatch,    // PRes payload size differs from the expected size
  kNodeNotConfigured,   // frame from / request for a node the MN does not know
  kNodeNotOperational,  // request needs the node operational
  kQueueFull,
  kLinkDown,
  kInvalidLayout,  // process image: duplicate slot, too many modules, MTU or size too large
  kPreqRegionOwnedByModule,    // raw PReq write overlaps the bytes of an X20DS1928 module (axis)
  kPreqOutOfRange,             // raw PReq write runs past the CN's PReq payload size
  kPreqWriteTooLong,           // raw PReq write longer than one request carries
  kModuleBlocksOverlap,        // process image: two modules of one CN share PRes or PReq bytes
  kModuleBlockOutsidePayload,  // process image: a module's block ends past the PRes/PReq size
  kLossOfPresThreshold,        // reset reason: the CN's loss-of-PRes counter reached its threshold
  kBootStepTimeout,            // reset reason: the CN did not finish a boot step in time
  kResetRequested,             // reset reason: the CN asked for its reset (NMTRequest)
  kNmtRequestRefused,          // an NMTRequest this MN does not serve (see docs/powerlink.md)
  kIdentityCheckFailed,  // reset reason: 0x1000/0x1018 read by SDO differs from the configuration
                         // or cannot be read
  kPrcNotSupported,      // a CN configured for PollResponse Chaining lacks the PRC feature flag:
                         // polled with PReq/PRes instead
  kPrcSyncFailed,        // reset reason: PRC set-up (SyncRequest/SyncResponse) failed twice, or
                         // the CN reports another PRes time than assigned
  kConfigurationNotVerified,  // after NMTResetConfiguration the CN's IdentResponse reports
                              // another configuration date/time (0x1020) than expected
                              // (0x1F26/0x1F27): it lost the download (power cycle), written again
  kPdoMappingEntryInvalid,    // process image: a PDO mapping entry's length or offset is unusable
  kPdoRegisterNotMapped,      // process image: the PDO mapping lacks a register an axis needs
};

[[nodiscard]] const std::error_category& frame_category() noexcept;
[[nodiscard]] const std::error_category& sdo_category() noexcept;
[[nodiscard]] const std::error_category& mn_category() noexcept;

[[nodiscard]] inline std::error_code make_error_code(FrameError e) noexcept {
  return {static_cast<int>(e), frame_category()};
}
[[nodiscard]] inline std::error_code make_error_code(SdoError e) noexcept {
  return {static_cast<int>(e), sdo_category()};
}
[[nodiscard]] inline std::error_code make_error_code(MnError e) noexcept {
  return {static_cast<int>(e), mn_category()};
}
// The abort code to send for an error: its own code for an abort error (core/sdo_abort.hpp,
// make_sdo_abort_error), timeout and out of memory for those SdoErrors, else general error.
[[nodiscard]] uint32_t to_sdo_abort_code(std::error_code ec) noexcept;

}  // namespace ds1928::powerlink

namespace std {
template <>
struct is_error_code_enum<ds1928::powerlink::FrameError> : true_type {};
template <>
struct is_error_code_enum<ds1928::powerlink::SdoError> : true_type {};
template <>
struct is_error_code_enum<ds1928::powerlink::MnError> : true_type {};
}  // namespace std
