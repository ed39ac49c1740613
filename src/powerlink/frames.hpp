// POWERLINK frame codec (EPSG DS 301 layout, docs: /work/shared/spec/powerlink.md §2–4).
// Pure: bytes in, values out. Builders write a complete Ethernet frame (without FCS) into the
// caller's span, padded with zeros to 60 bytes, and return its length. Parsers validate a whole
// received frame and return views (spans) into it; they never read past the span and never
// allocate. Offsets below count from byte 0 of the Ethernet frame; fields are little-endian.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <ranges>
#include <span>
#include <string_view>
#include <type_traits>
#include <variant>

#include "powerlink/errors.hpp"

namespace ds1928::powerlink {

inline constexpr uint16_t kEtherType = 0x88AB;
// Builders pad to Ethernet's minimum (60 bytes before the FCS). Parsers accept shorter frames
// whose message is complete: software senders on veth/TAP links send them unpadded.
inline constexpr std::size_t kMinFrameSize = 60;
inline constexpr std::size_t kHeaderSize = 17;  // Ethernet header + type, destination, source
inline constexpr std::size_t kSocSize = 36;
inline constexpr std::size_t kSoaSize = 23;
inline constexpr std::size_t kMaxFrameSize = 1514;  // before the FCS
inline constexpr std::size_t kMaxIsoPayload = 1490;
inline constexpr std::size_t kPollPayloadOffset = 24;  // PReq/PRes payload
inline constexpr std::size_t kAsndDataOffset = 18;     // ASnd service data
inline constexpr std::size_t kIdentResponseSize = 176;
inline constexpr std::size_t kStatusResponseMinSize = 72;
inline constexpr std::size_t kStatusEntryOffset = 32;
inline constexpr std::size_t kErrorEntrySize = 20;
inline constexpr std::size_t kSdoSeqOffset = 18;
inline constexpr std::size_t kSdoCmdOffset = 22;
inline constexpr std::size_t kSdoPayloadOffset = 30;
inline constexpr std::size_t kSdoCmdHeaderSize = 8;
// Largest SDO command payload one frame carries.
inline constexpr std::size_t kMaxSdoSegment = kMaxFrameSize - kSdoPayloadOffset;
// The SDO command payload a frame of at most AsyncMTU bytes (NMT_CycleTiming_REC.AsyncMTU_U16,
// counted after the 14-byte Ethernet header) carries, the initiate segment's 4-byte size
// included: every asynchronous frame of the network keeps to AsyncMTU (EPSG DS 301).
[[nodiscard]] constexpr std::size_t sdo_segment_for_async_mtu(std::size_t async_mtu) noexcept {
  const std::size_t frame = 14 + async_mtu < kMaxFrameSize ? 14 + async_mtu : kMaxFrameSize;
  return frame - kSdoPayloadOffset - 4;
}
inline constexpr uint8_t kEplVersion = 0x20;

inline constexpr uint8_t kNodeInvalid = 0;
inline constexpr uint8_t kNodeMaxCn = 239;
inline constexpr uint8_t kNodeMn = 240;
inline constexpr uint8_t kNodeDummy = 252;
inline constexpr uint8_t kNodeDiagnostic = 253;
inline constexpr uint8_t kNodeRouter = 254;
inline constexpr uint8_t kNodeBroadcast = 255;

using MacAddress = std::array<uint8_t, 6>;
inline constexpr MacAddress kMacSoc{0x01, 0x11, 0x1E, 0x00, 0x00, 0x01};
inline constexpr MacAddress kMacPRes{0x01, 0x11, 0x1E, 0x00, 0x00, 0x02};
inline constexpr MacAddress kMacSoA{0x01, 0x11, 0x1E, 0x00, 0x00, 0x03};
inline constexpr MacAddress kMacAsnd{0x01, 0x11, 0x1E, 0x00, 0x00, 0x04};

enum class MessageType : uint8_t {
  kSoC = 0x01,
  kPReq = 0x03,
  kPRes = 0x04,
  kSoA = 0x05,
  kASnd = 0x06
};
// The message type's name as DS 301 writes it ("SoC", "PReq", ...); "frame" for another value.
[[nodiscard]] std::string_view to_string(MessageType t) noexcept;

enum class NmtState : uint8_t {
  kOff = 0x00,
  kInitialising = 0x19,
  kResetApplication = 0x29,
  kResetCommunication = 0x39,
  kResetConfiguration = 0x79,
  kNotActive = 0x1C,
  kPreOperational1 = 0x1D,
  kPreOperational2 = 0x5D,
  kReadyToOperate = 0x6D,
  kOperational = 0xFD,
  kStopped = 0x4D,
  kBasicEthernet = 0x1E,
};
[[nodiscard]] bool is_valid_nmt_state(uint8_t raw) noexcept;
[[nodiscard]] std::string_view to_string(NmtState s) noexcept;

enum class NmtCommandId : uint8_t {
  kStartNode = 0x21,
  kStopNode = 0x22,
  kEnterPreOperational2 = 0x23,
  kEnableReadyToOperate = 0x24,
  kResetNode = 0x28,
  kResetCommunication = 0x29,
  kResetConfiguration = 0x2A,
  kSwReset = 0x2B,
};
[[nodiscard]] std::string_view to_string(NmtCommandId c) noexcept;

// SoA RequestedServiceID.
enum class RequestedService : uint8_t {
  kNone = 0x00,
  kIdentRequest = 0x01,
  kStatusRequest = 0x02,
  kNmtRequestInvite = 0x03,
  kSyncRequest = 0x06,
  kUnspecifiedInvite = 0xFF,
};

// ASnd ServiceID.
enum class AsndService : uint8_t {
  kIdentResponse = 0x01,
  kStatusResponse = 0x02,
  kNmtRequest = 0x03,
  kNmtCommand = 0x04,
  kSdo = 0x05,
  kSyncResponse = 0x06,
};

// Ethernet + POWERLINK basic header (bytes 0–16). Builders set `type` themselves.
struct FrameHeader {
  MacAddress dst_mac{};
  MacAddress src_mac{};
  MessageType type = MessageType::kSoC;
  uint8_t dst_node = kNodeBroadcast;
  uint8_t src_node = kNodeMn;
};

struct NetTime {
  uint32_t seconds = 0;
  uint32_t nanoseconds = 0;
  friend bool operator==(const NetTime&, const NetTime&) = default;
};

struct Soc {
  bool multiplexed_cycle_completed = false;  // MC
  bool prescaled_slot = false;               // PS
  NetTime net_time;
  uint64_t relative_time_us = 0;
};

struct PReq {
  bool multiplexed_slot = false;       // MS
  bool exception_acknowledge = false;  // EA
  bool ready = false;                  // RD: payload valid
  uint8_t pdo_version = 0;
  std::span<const uint8_t> payload;  // ≤ 1490 bytes
};

struct PRes {
  NmtState nmt_state = NmtState::kNotActive;
  bool multiplexed_slot = false;  // MS
  bool exception_new = false;     // EN
  bool ready = false;             // RD
  uint8_t priority = 0;           // PR 0..7
  uint8_t request_count = 0;      // RS 0..7
  uint8_t pdo_version = 0;
  std::span<const uint8_t> payload;
};

struct SoA {
  NmtState mn_nmt_state = NmtState::kPreOperational1;
  bool exception_acknowledge = false;  // EA
  bool exception_reset = false;        // ER
  RequestedService service = RequestedService::kNone;
  uint8_t target = kNodeInvalid;
  uint8_t epl_version = kEplVersion;
};

struct IdentResponse {
  bool exception_new = false;
  uint8_t priority = 0;
  uint8_t request_count = 0;
  NmtState nmt_state = NmtState::kPreOperational1;
  uint8_t epl_version = kEplVersion;
  uint32_t feature_flags = 0;
  uint16_t mtu = 300;
  uint16_t poll_in_size = 0;   // PRes payload the CN sends
  uint16_t poll_out_size = 0;  // PReq payload the CN expects
  uint32_t response_time_ns = 0;
  uint32_t device_type = 0;
  uint32_t vendor_id = 0;
  uint32_t product_code = 0;
  uint32_t revision_no = 0;
  uint32_t serial_no = 0;
  std::array<uint8_t, 8> vendor_ext1{};
  uint32_t verify_conf_date = 0;
  uint32_t verify_conf_time = 0;
  uint32_t app_sw_date = 0;
  uint32_t app_sw_time = 0;
  uint32_t ip_address = 0;  // as on the wire (first octet in the lowest byte)
  uint32_t subnet_mask = 0;
  uint32_t default_gateway = 0;
  std::array<char, 32> host_name{};
  std::array<uint8_t, 48> vendor_ext2{};
};

struct ErrorEntry {
  uint16_t type = 0;  // 0 terminates the list
  uint16_t code = 0;
  uint64_t timestamp = 0;  // NetTime: seconds in the low word, nanoseconds in the high word
  std::array<uint8_t, 8> additional{};
  friend bool operator==(const ErrorEntry&, const ErrorEntry&) = default;
};

struct StatusResponse {
  bool exception_new = false;    // EN
  bool exception_clear = false;  // EC
  uint8_t priority = 0;
  uint8_t request_count = 0;
  NmtState nmt_state = NmtState::kPreOperational2;
  uint64_t static_error_bits = 0;
  // Raw error entries (20 bytes each) up to, not including, the terminating type-0 entry.
  std::span<const uint8_t> entries;
  [[nodiscard]] std::size_t entry_count() const noexcept {
    return entries.size() / kErrorEntrySize;
  }
  // Precondition: i < entry_count().
  [[nodiscard]] ErrorEntry entry(std::size_t i) const noexcept;
};

struct NmtCommand {
  uint8_t command = 0;  // NmtCommandId for the plain commands; others carried raw
  std::span<const uint8_t> data;
};

struct NmtRequest {
  uint8_t command = 0;  // requested NMT command
  uint8_t target = 0;   // node the command is for
  std::span<const uint8_t> data;
};

// SDO sequence layer (bytes 18–21).
enum class SdoRecvCon : uint8_t { kNone = 0, kInit = 1, kValid = 2, kError = 3 };
enum class SdoSendCon : uint8_t { kNone = 0, kInit = 1, kValid = 2, kValidAckRequest = 3 };
struct SdoSequence {
  uint8_t recv_seq = 0;  // 0..63
  SdoRecvCon recv_con = SdoRecvCon::kNone;
  uint8_t send_seq = 0;  // 0..63
  SdoSendCon send_con = SdoSendCon::kNone;
};

// SDO command layer (bytes 22–29 header, 30… payload).
enum class SdoSegmentation : uint8_t { kExpedited = 0, kInitiate = 1, kSegment = 2, kComplete = 3 };
enum class SdoCommandId : uint8_t { kNil = 0x00, kWriteByIndex = 0x01, kReadByIndex = 0x02 };
struct SdoCommand {
  uint8_t transaction_id = 0;
  bool response = false;
  bool abort = false;
  SdoSegmentation segmentation = SdoSegmentation::kExpedited;
  uint8_t command_id = 0;  // SdoCommandId; others are carried raw (a server aborts them)
  // Initiate segments only: the transfer's total data size (u32 at the start of the payload).
  uint32_t total_size = 0;
  // Bytes after the header (and after the total size of an initiate segment). For an abort:
  // the 4-byte abort code.
  std::span<const uint8_t> payload;
};

struct Sdo {
  SdoSequence sequence;
  // False for sequence-layer-only frames (handshake, acknowledgements): the command header is
  // all zero (Nil command, size 0) — which is also what the 60-byte padding leaves there.
  bool has_command = false;
  SdoCommand command;
};

// ASnd services the MN does not interpret (SyncResponse); the bytes from offset 18.
struct AsndRaw {
  AsndService service = AsndService::kSyncResponse;
  std::span<const uint8_t> data;
};

using AsndBody = std::variant<IdentResponse, StatusResponse, NmtRequest, NmtCommand, Sdo, AsndRaw>;
struct Asnd {
  AsndService service = AsndService::kSdo;
  AsndBody body;
};

using Message = std::variant<Soc, PReq, PRes, SoA, Asnd>;
struct Frame {
  FrameHeader header;
  Message message;
};

// ---- Build ------------------------------------------------------------------------------------
// Each returns the frame length (≥ 60, bytes beyond the message zeroed) or kBufferTooSmall /
// kPayloadTooLarge. `header.type` is ignored; the right MessageType is written.

[[nodiscard]] Result<std::size_t> build_soc(std::span<uint8_t> out, const FrameHeader& header,
                                            const Soc& soc) noexcept;
[[nodiscard]] Result<std::size_t> build_preq(std::span<uint8_t> out, const FrameHeader& header,
                                             const PReq& preq) noexcept;
[[nodiscard]] Result<std::size_t> build_pres(std::span<uint8_t> out, const FrameHeader& header,
                                             const PRes& pres) noexcept;
[[nodiscard]] Result<std::size_t> build_soa(std::span<uint8_t> out, const FrameHeader& header,
                                            const SoA& soa) noexcept;
[[nodiscard]] Result<std::size_t> build_ident_response(std::span<uint8_t> out,
                                                       const FrameHeader& header,
                                                       const IdentResponse& ident) noexcept;
// Writes `entries` followed by a terminating type-0 entry (frame ≥ 72 bytes).
[[nodiscard]] Result<std::size_t> build_status_response(
    std::span<uint8_t> out, const FrameHeader& header, const StatusResponse& status,
    std::span<const ErrorEntry> entries) noexcept;
[[nodiscard]] Result<std::size_t> build_nmt_command(std::span<uint8_t> out,
                                                    const FrameHeader& header,
                                                    const NmtCommand& command) noexcept;
[[nodiscard]] Result<std::size_t> build_nmt_request(std::span<uint8_t> out,
                                                    const FrameHeader& header,
                                                    const NmtRequest& request) noexcept;
// `sdo.has_command` false writes the sequence layer only. For an initiate segment the total size
// is written before the payload; segment size = payload bytes after the 8-byte header.
[[nodiscard]] Result<std::size_t> build_sdo(std::span<uint8_t> out, const FrameHeader& header,
                                            const Sdo& sdo) noexcept;

// Standard addressing for a frame sent by node `src_node` (MN: 240) from `src_mac`: multicast
// MACs for SoC/PRes/SoA/ASnd, `dst_mac` for PReq (the CN's unicast MAC).
[[nodiscard]] FrameHeader soc_header(const MacAddress& src_mac) noexcept;
[[nodiscard]] FrameHeader soa_header(const MacAddress& src_mac) noexcept;
[[nodiscard]] FrameHeader preq_header(const MacAddress& src_mac, const MacAddress& dst_mac,
                                      uint8_t cn_node) noexcept;
[[nodiscard]] FrameHeader pres_header(const MacAddress& src_mac, uint8_t cn_node) noexcept;
[[nodiscard]] FrameHeader asnd_header(const MacAddress& src_mac, uint8_t src_node,
                                      uint8_t dst_node) noexcept;

// ---- Parse ------------------------------------------------------------------------------------
// parse_frame() validates the Ethernet/POWERLINK header, the size limits and the message's own
// consistency (node ids, payload sizes, NMT state, service ids, SDO sizes). A frame shorter than
// 60 bytes is accepted when its message's fields are all there (is_short_frame() lets callers
// count them); one that ends inside them gets the message's kXxxTruncated error. The spans in
// the result point into `frame`.

[[nodiscard]] Result<FrameHeader> parse_header(std::span<const uint8_t> frame) noexcept;
[[nodiscard]] constexpr bool is_short_frame(std::size_t length) noexcept {
  return length < kMinFrameSize;
}
[[nodiscard]] Result<Frame> parse_frame(std::span<const uint8_t> frame) noexcept;

// Typed shortcuts: kWrongMessageType (or kUnknownServiceId for ASnd services) when the frame is
// valid but of another kind.
[[nodiscard]] Result<Soc> parse_soc(std::span<const uint8_t> frame) noexcept;
[[nodiscard]] Result<PReq> parse_preq(std::span<const uint8_t> frame) noexcept;
[[nodiscard]] Result<PRes> parse_pres(std::span<const uint8_t> frame) noexcept;
[[nodiscard]] Result<SoA> parse_soa(std::span<const uint8_t> frame) noexcept;
[[nodiscard]] Result<Asnd> parse_asnd(std::span<const uint8_t> frame) noexcept;

// The results view the frame's bytes, so a frame that dies at the end of the call (a temporary
// container) would leave them dangling: such calls do not compile. Spans and lvalues pass.
template <class R>
concept DanglingFrame = !std::is_lvalue_reference_v<R> && !std::ranges::borrowed_range<R>;
template <class R>
requires DanglingFrame<R> Result<Frame> parse_frame(R&&)
= delete;
template <class R>
requires DanglingFrame<R> Result<PRes> parse_pres(R&&)
= delete;
template <class R>
requires DanglingFrame<R> Result<PReq> parse_preq(R&&)
= delete;
template <class R>
requires DanglingFrame<R> Result<Asnd> parse_asnd(R&&)
= delete;

// Ordered little-endian helpers shared by the codec and process-image code.
[[nodiscard]] constexpr uint16_t load_le16(const uint8_t* p) noexcept {
  return static_cast<uint16_t>(p[0] | (p[1] << 8));
}
[[nodiscard]] constexpr uint32_t load_le32(const uint8_t* p) noexcept {
  return static_cast<uint32_t>(p[0]) | (static_cast<uint32_t>(p[1]) << 8) |
         (static_cast<uint32_t>(p[2]) << 16) | (static_cast<uint32_t>(p[3]) << 24);
}
[[nodiscard]] constexpr uint64_t load_le64(const uint8_t* p) noexcept {
  return static_cast<uint64_t>(load_le32(p)) | (static_cast<uint64_t>(load_le32(p + 4)) << 32);
}
constexpr void store_le16(uint8_t* p, uint16_t v) noexcept {
  p[0] = static_cast<uint8_t>(v);
  p[1] = static_cast<uint8_t>(v >> 8);
}
constexpr void store_le32(uint8_t* p, uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
constexpr void store_le64(uint8_t* p, uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

}  // namespace ds1928::powerlink
