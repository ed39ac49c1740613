// Error codes of the POWERLINK layer (own std::error_category, Lely style) and a small
// expected-like result type: parse and build calls return a value or a named error, never throw.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <system_error>
#include <type_traits>
#include <utility>

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
};

[[nodiscard]] const std::error_category& frame_category() noexcept;
[[nodiscard]] const std::error_category& sdo_category() noexcept;
[[nodiscard]] const std::error_category& sdo_abort_category() noexcept;
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
// An SDO abort code (0x0504'0000 ...) as an error: value() is the code bit pattern.
[[nodiscard]] inline std::error_code make_sdo_abort_error(uint32_t abort_code) noexcept {
  return {static_cast<int>(abort_code), sdo_abort_category()};
}
// The abort code to send for an error (its own code for an abort error, else general error).
[[nodiscard]] uint32_t to_sdo_abort_code(std::error_code ec) noexcept;

// Expected-like result: a value or an error_code, no exceptions.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}     // NOLINT(google-explicit-constructor)
  Result(std::error_code error) : error_(error) {}  // NOLINT(google-explicit-constructor)
  template <class E, std::enable_if_t<std::is_error_code_enum_v<E>, int> = 0>
  Result(E error) : error_(make_error_code(error)) {}  // NOLINT(google-explicit-constructor)

  [[nodiscard]] bool has_value() const noexcept { return value_.has_value(); }
  explicit operator bool() const noexcept { return has_value(); }
  // Precondition: has_value().
  [[nodiscard]] const T& value() const& noexcept { return *value_; }
  [[nodiscard]] T& value() & noexcept { return *value_; }
  [[nodiscard]] const T& operator*() const noexcept { return *value_; }
  [[nodiscard]] const T* operator->() const noexcept { return &*value_; }
  [[nodiscard]] std::error_code error() const noexcept { return error_; }

 private:
  std::optional<T> value_;
  std::error_code error_;
};

}  // namespace ds1928::powerlink

namespace std {
template <>
struct is_error_code_enum<ds1928::powerlink::FrameError> : true_type {};
template <>
struct is_error_code_enum<ds1928::powerlink::SdoError> : true_type {};
template <>
struct is_error_code_enum<ds1928::powerlink::MnError> : true_type {};
}  // namespace std
