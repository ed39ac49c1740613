// PollResponse Chaining frames (EPSG DS 302-C): the SyncRequest (an SoA with RequestedServiceID 6
// and a payload from byte 24) and the SyncResponse (ASnd ServiceID 6). Pure, like frames.hpp:
// builders write a whole frame padded to 60 bytes, parsers read views of a received one.
//
// SyncRequest payload (offsets in the Ethernet frame, little endian):
//   24 SyncControl u32 | 28 PResTimeFirst ns | 32 PResTimeSecond ns | 36 SyncMNDelayFirst ns |
//   40 SyncMNDelaySecond ns | 44 PResFallBackTimeout ns | 48 DestMacAddress[6]   (54 bytes)
// SyncResponse (from byte 18):
//   18 reserved u16 | 20 SyncStatus u32 | 24 Latency ns | 28 SyncNodeNumber u32 |
//   32 SyncDelay ns | 36 PResTimeFirst ns | 40 PResTimeSecond ns                  (44 bytes)
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "powerlink/frames.hpp"

namespace ds1928::powerlink {

inline constexpr std::size_t kSyncRequestSize = 54;
inline constexpr std::size_t kSyncResponseSize = 44;

// SyncControl bits of a SyncRequest.
namespace sync_control {
inline constexpr uint32_t kPResTimeFirstValid = 0x00000001;
inline constexpr uint32_t kPResTimeSecondValid = 0x00000002;
inline constexpr uint32_t kSyncMnDelayFirstValid = 0x00000004;
inline constexpr uint32_t kSyncMnDelaySecondValid = 0x00000008;
inline constexpr uint32_t kPResFallBackTimeoutValid = 0x00000010;
inline constexpr uint32_t kDestMacAddressValid = 0x00000020;
inline constexpr uint32_t kPResModeReset = 0x40000000;
inline constexpr uint32_t kPResModeSet = 0x80000000;
}  // namespace sync_control

// SyncStatus bits of a SyncResponse.
namespace sync_status {
inline constexpr uint32_t kPResTimeFirstValid = 0x00000001;
inline constexpr uint32_t kPResTimeSecondValid = 0x00000002;
inline constexpr uint32_t kPResModeStatus = 0x80000000;  // the CN is in PRC mode
}  // namespace sync_status

// The CN feature flag (NMT_FeatureFlags_U32, IdentResponse byte 24) for PRC. (The MN's side,
// NodeAssignment's PRC bit, is in concise_dcf.hpp.)
inline constexpr uint32_t kFeatureFlagPrc = 0x00040000;

struct SyncRequest {
  NmtState mn_nmt_state = NmtState::kPreOperational2;
  bool exception_acknowledge = false;
  bool exception_reset = false;
  uint8_t target = kNodeInvalid;
  uint32_t sync_control = 0;
  uint32_t pres_time_first_ns = 0;
  uint32_t pres_time_second_ns = 0;
  uint32_t sync_mn_delay_first_ns = 0;
  uint32_t sync_mn_delay_second_ns = 0;
  uint32_t pres_fallback_timeout_ns = 0;
  MacAddress dest_mac{};
};

struct SyncResponse {
  uint32_t sync_status = 0;
  uint32_t latency_ns = 0;        // the CN's constant response latency
  uint32_t sync_node_number = 0;  // node of the last SyncRequest/SyncResponse pair it measured
  uint32_t sync_delay_ns = 0;     // end of that SyncRequest to the start of that SyncResponse
  uint32_t pres_time_first_ns = 0;
  uint32_t pres_time_second_ns = 0;
};

// A SoA inviting `req.target` to a SyncResponse (header: soa_header()).
[[nodiscard]] Result<std::size_t> build_sync_request(std::span<uint8_t> out,
                                                     const FrameHeader& header,
                                                     const SyncRequest& req) noexcept;
// kWrongMessageType for a frame that is no SoA with RequestedServiceID 6.
[[nodiscard]] Result<SyncRequest> parse_sync_request(std::span<const uint8_t> frame) noexcept;

[[nodiscard]] Result<std::size_t> build_sync_response(std::span<uint8_t> out,
                                                      const FrameHeader& header,
                                                      const SyncResponse& res) noexcept;
// From the ASnd service data (bytes from offset 18, as AsndRaw::data carries them).
[[nodiscard]] Result<SyncResponse> parse_sync_response(std::span<const uint8_t> data) noexcept;

// Wire time of a frame with a `payload`-byte PDO at 100 Mbit/s as DS 302-C counts it for PRes
// response times: (payload + 10-byte PDO header + 18-byte Ethernet wrapper) × 80 ns + 640 ns
// preamble; the minimum frame counts 46 payload bytes.
[[nodiscard]] constexpr uint32_t prc_frame_time_ns(std::size_t payload) noexcept {
  const std::size_t bytes = payload + 10 + 18 < 64 ? 64 : payload + 10 + 18;
  return static_cast<uint32_t>(bytes * 80 + 640);
}
inline constexpr uint32_t kInterFrameGapNs = 960;

}  // namespace ds1928::powerlink
