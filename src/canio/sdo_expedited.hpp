// CANopen expedited SDO (CiA 301 §7.2.4.3): the acyclic register access of CAN-I/O bus
// controllers with a CANopen object dictionary. Only expedited transfers (1..4 data bytes in the
// initiate frame) are built and accepted; every X20DS1928 register is 1, 2 or 4 bytes.
//
// Client → server on COB-ID 0x600 + node, server → client on 0x580 + node, always 8 data bytes:
//   byte 0  command specifier: ccs/scs in bits 7..5, n (bytes without data) in 3..2,
//           e (expedited) bit 1, s (size indicated) bit 0
//   bytes 1..2  index (little endian), byte 3 subindex, bytes 4..7 data or abort code (LE).
//   initiate download request  0x23/0x27/0x2B/0x2F (4/3/2/1 bytes)  → response 0x60
//   initiate upload request    0x40                                 → response 0x43/0x47/0x4B/0x4F
//   abort transfer             0x80 + 32-bit abort code (either direction)
#pragma once

#include <cstdint>
#include <system_error>

#include "can/can_frame.hpp"
#include "can/errors.hpp"
#include "core/sdo_abort.hpp"

namespace ds1928::canio {

inline constexpr uint32_t kSdoRequestBase = 0x600;   // client → server: 0x600 + node
inline constexpr uint32_t kSdoResponseBase = 0x580;  // server → client: 0x580 + node

enum class SdoCommand : uint8_t {
  DownloadRequest = 0,   // write, client → server
  UploadRequest = 1,     // read, client → server
  DownloadResponse = 2,  // write acknowledged
  UploadResponse = 3,    // read answered with data
  Abort = 4,             // either side gives up, with an abort code
};

struct SdoMessage {
  SdoCommand command = SdoCommand::UploadRequest;
  uint16_t index = 0;
  uint8_t subindex = 0;
  uint8_t size = 0;    // data bytes 1..4 for DownloadRequest / UploadResponse, else 0
  uint32_t value = 0;  // data (little endian in the frame) or abort code
  // UploadResponse / DownloadRequest: false when the frame said "expedited, size not indicated"
  // (CiA 301: e = 1, s = 0; the data is up to 4 bytes, `size` is then 4). The client takes such
  // an answer by the size it expects (match_sdo_response()).
  bool size_indicated = true;
  friend bool operator==(const SdoMessage&, const SdoMessage&) = default;
};

// What made an SDO frame unusable or a response not the answer to the request.
enum class SdoFrameError : int {
  kInvalidNode = 1,        // node id outside 1..127
  kInvalidSize,            // expedited data size outside 1..4
  kWrongCobId,             // not 0x600 + node / 0x580 + node of the expected node
  kWrongLength,            // dlc is not 8
  kRemoteOrErrorFrame,     // an RTR or error frame on an SDO identifier
  kUnknownCommand,         // command specifier not defined for this direction
  kSegmentedNotSupported,  // a normal (segmented) transfer: only expedited is supported
  kCommandMismatch,        // the response's command does not answer the request's
  kIndexMismatch,          // the response names another index
  kSubindexMismatch,       // the response names another subindex
  kSizeMismatch,           // upload response with another data size than requested
};

[[nodiscard]] const std::error_category& sdo_frame_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(SdoFrameError e) noexcept {
  return {static_cast<int>(e), sdo_frame_category()};
}

// Frames. node 1..127; size 1..4 (value's low bytes are sent, little endian).
[[nodiscard]] Result<CanFrame> build_sdo_request(uint8_t node, const SdoMessage& message) noexcept;
[[nodiscard]] Result<CanFrame> build_sdo_response(uint8_t node, const SdoMessage& message) noexcept;

// Parses a frame seen on 0x600 + node (from_server false) or 0x580 + node (from_server true).
[[nodiscard]] Result<SdoMessage> parse_sdo(uint8_t node, bool from_server,
                                           const CanFrame& frame) noexcept;

// The client's view: is `response` the answer to `request` (sent to `node`)? On success the
// response message (UploadResponse with the value, or DownloadResponse). An abort from the
// server for the same index/subindex is the abort code as error (core/sdo_abort.hpp); anything
// else that does not match is an SdoFrameError naming why. expected_size 0: any 1..4 accepted.
// An upload response with "size not indicated" is taken by expected_size (its low bytes; CiA 301
// allows the server to leave the size open in an expedited transfer).
[[nodiscard]] Result<SdoMessage> match_sdo_response(uint8_t node, const SdoMessage& request,
                                                    const CanFrame& response,
                                                    uint8_t expected_size = 0) noexcept;

}  // namespace ds1928::canio

namespace std {
template <>
struct is_error_code_enum<ds1928::canio::SdoFrameError> : true_type {};
}  // namespace std
