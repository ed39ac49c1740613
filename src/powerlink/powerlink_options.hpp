// What the POWERLINK Managing Node is told about its segment: interface, CNs, DLL thresholds,
// NMT timing, receive strategy, SDO mapping (docs/powerlink.md). The configuration's
// `powerlink:` section fills it (src/config); the daemon hands it to the MN in MnConfig.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ds1928 {

// One object the MN writes to a CN by SDO in the boot step "configure" (little endian bytes).
struct CnObjectWrite {
  uint16_t index = 0;
  uint8_t subindex = 0;
  std::vector<uint8_t> data;
  bool from_cdc = false;  // from a concise DCF (else from the YAML `sdo_writes`)
  friend bool operator==(const CnObjectWrite&, const CnObjectWrite&) = default;
};

// The bus controller's object scheme: which object of the CN holds which register of the
// X20DS1928 in which slot (docs/powerlink.md §Process image from the PDO mapping). The inputs of
// slot s are object input_index + s, its outputs output_index + s; the sub-indices per register
// are a table (powerlink/pdo_image.hpp). The default is an assumption.
struct PdoObjectScheme {
  uint16_t input_index = 0x2000;
  uint16_t output_index = 0x2100;
  friend bool operator==(const PdoObjectScheme&, const PdoObjectScheme&) = default;
};
// Where a CN's modules sit in its PRes/PReq.
enum class ImageLayout : uint8_t {
  kAuto,     // from the PDO mapping the node's objects write (0x1A00/0x1600), else packed
  kPacked,   // packed in slot order (or at pres_offset/preq_offset): the simulator, older setups
  kMapping,  // from the PDO mapping the node's objects write; refused without one
};

// POWERLINK Controlled Node as the MN sees it.
inline constexpr uint32_t kDefaultPresLatencyUs = 2;

struct PowerlinkNodeConfig {
  uint8_t node_id = 1;
  // Identity (docs/powerlink.md §Third-party CNs): checked in the IdentResponse and read back
  // by SDO (0x1000, 0x1018/1..4) before the node is configured.
  std::optional<uint32_t> vendor_id;
  std::optional<uint32_t> product_code;
  std::optional<uint32_t> device_type;
  std::optional<uint32_t> revision_no;
  std::optional<uint32_t> serial_no;
  std::string cdc;  // concise DCF of this CN (the content of the MN's 0x1F22/node), as given
  // Written in this order in the boot step "configure": the CN's concise DCF (node `cdc`, else
  // 0x1F22/node of powerlink.cdc), the cycle objects (cycle_objects), then `sdo_writes`.
  std::vector<CnObjectWrite> object_writes;
  // CFM_ExpConfDateList/TimeList (0x1F26/0x1F27 /node): the configuration date and time the CN
  // reports in its IdentResponse (its 0x1020/1, /2) once it took the download (which writes
  // them). Set (either one), the MN checks them after its NMTResetConfiguration and writes the
  // configuration again when they differ. Unset: not checked.
  std::optional<uint32_t> expected_conf_date;
  std::optional<uint32_t> expected_conf_time;
  bool cycle_objects = false;  // write 0x1006 and 0x1F98/4,5 from the configuration
  // PResTimeout (0x1F92/node): how long the MN waits for the PRes after the PReq. Long enough for
  // a CN that answers from software on a busy PC (docs/realtime.md); a lost PRes costs it once.
  uint32_t pres_timeout_us = 200;
  // How soon the CN answers a PReq (end of PReq to start of PRes) when all is well: the cycle
  // budget's nominal figure counts this instead of the timeout. The default is a hardware CN's:
  // seed 001's gap between PReq and PRes (about 2 µs) and PResMaxLatency_U32 (0x1F98/3) of
  // openPOWERLINK's device descriptions (2000 ns).
  uint32_t pres_latency_us = kDefaultPresLatencyUs;
  // DLL_MNCNLossPResThreshold (0x1C09/node); unset: powerlink.thresholds.loss_of_pres.
  std::optional<uint32_t> loss_of_pres_threshold;
  bool mandatory = true;
  // Multiplexed (EPSG DS 301): polled in one cycle of each multiplexed cycle of
  // PowerlinkBusConfig::multiplex_cycles, its slot (NMT_MultiplCycleAssign 0x1F9B/node,
  // 1..multiplex_cycles); unset with `multiplexed`, the MN assigns one (the least loaded, lowest
  // first, in node-id order) and reports it.
  bool multiplexed = false;
  std::optional<uint8_t> multiplex_slot;
  // PollResponse Chaining (EPSG DS 302-C): the CN sends its PRes at an assigned time after the
  // MN's PResMN instead of after a PReq (NodeAssignment 0x1F81/node bit 14 of the MN's CDC).
  // A CN without the PRC feature flag is polled with PReq/PRes instead (reported).
  bool prc = false;
  std::optional<uint16_t> preq_size;  // default: from IdentResponse PollOutSize / module list
  std::optional<uint16_t> pres_size;  // default: from IdentResponse PollInSize / module list
  ImageLayout layout = ImageLayout::kAuto;
  std::optional<PdoObjectScheme> object_scheme;  // unset: powerlink.object_scheme
};
// DLL threshold counters (+8 per cycle with the error, −1 per cycle without; 0 = disabled).
struct DllThresholds {
  // DLL_MNCNLossPResThreshold (0x1C09) of every CN without its own; unset: ride through
  // kLossOfPresRideThroughUs of silence, at least 5 lost PRes in a row, reset at the next loss
  // (default_loss_of_pres_threshold()).
  std::optional<uint32_t> loss_of_pres;
  uint32_t cycle_time_exceeded = 15;  // DLL_MNCycTimeExceed_REC (0x1C02/3)
  uint32_t late_pres = 15;
};
// A CN whose host stalls this long (PRes lost in a row) is not reset with the default threshold;
// measured stalls of a busy 2-core VM: 7–13 ms (docs/realtime.md).
inline constexpr uint32_t kLossOfPresRideThroughUs = 20'000;
[[nodiscard]] constexpr uint32_t default_loss_of_pres_threshold(uint32_t period_us) noexcept {
  // Fires at the first loss past the ride-through: 8 × (tolerated losses in a row + 1).
  const uint32_t cycles =
      period_us == 0 ? 5 : (kLossOfPresRideThroughUs + period_us - 1) / period_us;
  return 8 * ((cycles < 5 ? 5 : cycles) + 1);
}

// How the cycle thread waits for a PRes or an awaited ASnd (docs/realtime.md).
enum class RxWait : uint8_t {
  Block,     // RX ring, polled for rx_spin_us, then a blocking ppoll(): the CPU is free meanwhile
  Spin,      // RX ring polled until the frame or the deadline: no syscall, but nothing of lower
             // priority runs on the cycle thread's CPU until then
  BusyPoll,  // recv(MSG_DONTWAIT) in a loop until the deadline (no ring)
};
// The MN's NMT timing while booting CNs (docs/powerlink.md, boot sequence).
struct PowerlinkNmtConfig {
  // NOT_ACTIVE (MNWaitNotAct, 0x1F89/1): the MN listens this long before it sends anything; an
  // SoC, PReq or SoA of another MN then keeps it NOT_ACTIVE. 0: start at once. openPOWERLINK's MN
  // object dictionary has 1 s.
  uint32_t wait_not_active_ms = 1000;
  uint32_t pre_op1_timeout_ms = 500;     // reduced cycle before the MN starts full cycles
  uint32_t boot_step_timeout_ms = 5000;  // a CN stuck in a boot step is reset
  uint32_t reset_wait_ms = 100;          // after NMTResetNode, before identifying again
  uint32_t status_request_every = 8;     // cycles between StatusRequests to a booting CN
};

struct PowerlinkBusConfig {
  std::string interface;  // raw-socket interface, e.g. "eth1"
  std::string cdc;        // the MN's concise DCF (openCONFIGURATOR's mnobd.cdc), as given
  // An interface with an IP address or the default route is refused unless this is set: POWERLINK
  // wants a segment of its own (powerlink/interface_check.hpp).
  bool allow_shared_interface = false;
  std::vector<PowerlinkNodeConfig> nodes;
  DllThresholds thresholds;
  PowerlinkNmtConfig nmt;
  // AsyncSlotTimeout (0x1F8A/2): wait for the invited ASnd after the SoA.
  uint32_t async_timeout_us = 100;
  // AsyncMTU (NMT_CycleTiming_REC.AsyncMTU_U16, 0x1F98/8): the longest asynchronous frame of the
  // network, bytes after the Ethernet header (DS 301: 300..1500, default 300). The MN's own SDO
  // segments keep to it; the cycle budget counts one ASnd of it per cycle.
  uint16_t async_mtu = 300;
  // WaitSoCPReq (0x1F8A/1): pause between the SoC and the first PReq, for CNs that need time to
  // take the SoC (a software CN) before they can answer a PReq.
  uint32_t wait_soc_preq_us = 0;
  // NMT_CycleTiming.MultiplCycleCnt (0x1F98/7): cycles of one multiplexed cycle, written to every
  // multiplexed CN (the same value to all of them); 0 = no multiplexing.
  uint8_t multiplex_cycles = 0;
  // PResMN payload (NMT_CycleTiming PResActPayloadLimit, 0x1F98/5 of the MN): the MN's PRes after
  // the SoC when PRC nodes are present; 36 bytes fill the minimum frame.
  uint16_t pres_mn_size = 36;
  RxWait rx_wait = RxWait::Block;
  uint32_t rx_spin_us = 0;  // Block: poll the ring this long before blocking
  uint32_t sdo_timeout_ms = 500;
  // PosTime relation: PosTime = low 32 bits of (SoC RelativeTime µs + offset).
  int64_t nettime_offset_us = 0;
  // Register → (index, subindex) overrides; default scheme in docs/powerlink.md.
  std::map<uint16_t, std::pair<uint16_t, uint8_t>> sdo_overrides;
  PdoObjectScheme object_scheme;  // of every CN without its own
  // With the MN's concise DCF: for each key it can set ("cycle.period_us",
  // "powerlink.nodes[0].pres_timeout_us", ...) where the effective value came from: "yaml",
  // "default" or "cdc <object> = <value> (byte <offset>)". --print-config shows it.
  std::map<std::string, std::string> sources;
};

}  // namespace ds1928
