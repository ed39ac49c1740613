// ManagingNode's per-CN state (private to the managing_node*.cpp files, which split the MN by
// concern: NMT and cycle, SDO, asynchronous slot and error signalling).
#pragma once

#include <array>
#include <cstring>
#include <memory>
#include <vector>

#include "powerlink/error_signalling.hpp"
#include "powerlink/managing_node.hpp"

namespace ds1928::powerlink {

namespace mn_detail {
inline constexpr std::size_t kOutboxDepth = 4;
inline constexpr std::size_t kOpQueueDepth = 32;

// What an SDO transfer of a CN is for.
enum class OpKind : uint8_t {
  kRegister,      // a module register (boot configuration or a client's request)
  kIdentityRead,  // 0x1000 / 0x1018 read back and compared
  kObjectWrite,   // an object of the CN's configuration (concise DCF, sdo_writes, cycle objects)
  kMappingRead,   // the CN's own PDO mapping (0x1A00, 0x1600), read when none is written
};
// Entries of one PDO mapping the MN reads (DS 301: sub 1..254).
inline constexpr std::size_t kMaxReadMapEntries = kMaxPdoMapEntries;
// Reading the CN's own PDO mapping (boot step "configure"): TPDO, then RPDO, sub 0 then 1..n.
enum class MapRead : uint8_t { kTpdo, kRpdo, kDone };
// Where an object write's value comes from: fixed bytes, or what is known only at boot.
enum class ValueSource : uint8_t { kData, kCycleUs, kPreqSize, kPresSize };
struct ObjectOp {
  OpKind kind = OpKind::kObjectWrite;
  uint16_t index = 0;
  uint8_t subindex = 0;
  ValueSource source = ValueSource::kData;
  uint32_t expected = 0;  // identity read
  std::size_t data_offset = 0;
  std::size_t data_size = 0;
  // The RPDO of the PResMN: written only to a node chained by PRC (not after a fall-back).
  bool prc_only = false;
};
// A register request routed to the module in `slot` of the CN.
struct SlotRegister {
  uint8_t slot = 1;
  RegisterRequest request;
};
// PollResponse Chaining set-up of a CN (managing_node_prc.cpp), one SyncRequest per step.
enum class PrcStep : uint8_t {
  kOff,                 // polled with PReq/PRes (or not in the isochronous phase)
  kMeasurePredecessor,  // SyncRequest to the predecessor: the CN times its SyncResponse
  kMeasure,             // SyncRequest to the CN: its SyncDelay to the predecessor, its latency
  kAdd,                 // SyncRequest with PResModeSet and the PRes time
  kVerify,              // SyncRequest: the CN reports the PRes time it took
  kActive,
};
}  // namespace mn_detail
using namespace mn_detail;

struct ManagingNode::Cn {
  PowerlinkNodeConfig cfg;
  CnStatus* st = nullptr;
  NodeImageLayout layout;
  // Layout auto/mapping without a mapping written to the CN: its own is read by SDO at boot
  // (docs/powerlink.md §Process image from the PDO mapping) and bound through the scheme.
  bool read_mapping = false;
  NodeImageLayout packed_layout;      // until the CN's mapping is read (auto: if it maps no TPDO)
  std::vector<ModuleSpec> specs;      // the node's modules, for binding
  MapRead map_read = MapRead::kDone;  // kDone: read in this boot (or not to be read)
  uint8_t map_sub = 0;                // next sub-index to read
  uint8_t map_count = 0;              // sub 0 of the mapping being read
  std::array<PdoMapEntry, kMaxReadMapEntries> map_tpdo{};
  std::array<PdoMapEntry, kMaxReadMapEntries> map_rpdo{};
  uint8_t map_tpdo_count = 0;
  uint8_t map_rpdo_count = 0;
  std::array<uint8_t, kMaxIsoPayload> preq{};
  std::array<uint8_t, kMaxIsoPayload> pres{};
  uint8_t mux_slot = 0;          // slot of the multiplexed cycle, 0: polled every cycle
  bool polled = false;           // PReq sent this cycle
  uint32_t loss_threshold = 0;   // DLL_MNCNLossPResThreshold (0x1C09) in effect
  bool pres_seen = false;        // its PRes arrived this cycle
  bool pres_usable = false;      // ... with a payload the layout fits in and RD = 1
  bool outputs_written = false;  // the driver wrote the output image this cycle
  bool timed_out = false;        // the driver gave up waiting for it this cycle
  bool late = false;             // a PRes came after its timeout
  int64_t state_since_ns = 0;
  uint64_t last_status_request = 0;
  uint8_t rs = 0;  // CN's pending async requests (RS) and their priority (PR)
  uint8_t pr = 0;
  bool sdo_wait_answer = false;
  // Frames the MN sends to this CN in the async phase (NMT commands, SDO).
  std::array<std::array<uint8_t, kMaxFrameSize>, kOutboxDepth> outbox{};
  std::array<std::size_t, kOutboxDepth> outbox_len{};
  std::size_t outbox_head = 0;
  std::size_t outbox_count = 0;
  uint32_t outbox_overflows = 0;
  std::unique_ptr<SdoClient> sdo;
  // Boot step "configure", built once: identity reads and object writes first, then the module
  // registers. Object values live in object_data.
  std::vector<ObjectOp> object_ops;
  std::vector<uint8_t> object_data;
  std::size_t object_next = 0;
  std::vector<SlotRegister> boot_ops;  // module configuration
  std::size_t boot_next = 0;
  OpKind op_kind = OpKind::kRegister;
  std::array<uint8_t, 4> op_value{};  // value of a ValueSource other than kData
  MnErrorSignalling errsig;
  PrcStep prc_step = PrcStep::kOff;
  bool prc_wait = false;        // SyncRequest sent, SyncResponse awaited
  uint8_t prc_failures = 0;     // SyncResponses missed or wrong in a row
  uint8_t prc_measured_to = 0;  // the predecessor the last SyncRequest pair was for
  bool configuring = false;
  // Boot step "configure" wrote objects in this boot (successful SDO writes) ...
  uint32_t written = 0;
  // ... and NMTResetConfiguration made the CN take them: the next "configure" writes nothing
  // (until an NMTResetNode, which restores the CN's stored values).
  bool config_applied = false;
  std::array<SlotRegister, kOpQueueDepth> ops{};
  std::size_t ops_head = 0;
  std::size_t ops_count = 0;
  bool op_active = false;
  bool op_internal = false;
  SlotRegister current{};

  void push_outbox(std::span<const uint8_t> frame) noexcept {
    if (outbox_count == kOutboxDepth || frame.size() > kMaxFrameSize) {
      ++outbox_overflows;
      return;
    }
    const std::size_t i = (outbox_head + outbox_count) % kOutboxDepth;
    std::memcpy(outbox[i].data(), frame.data(), frame.size());
    outbox_len[i] = frame.size();
    ++outbox_count;
  }
};

}  // namespace ds1928::powerlink
