// The daemon's configuration as plain values with the datasheet's defaults. Loaded from one YAML
// file by load_config(); every field here is documented in docs/configuration.md.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/module_image.hpp"
#include "core/module_settings.hpp"

namespace ds1928 {

enum class BusKind : uint8_t { Simulated, Powerlink, Canio };
enum class MotionProfile : uint8_t { ConstantVelocity, Sine, Stop };

struct AxisConfig {
  std::string name;  // shown in status; default "axis<N>"
  uint8_t node = 1;  // POWERLINK CN node id / CAN-I/O node number / sim node
  uint8_t slot = 1;  // module position behind the bus controller (1-based)
  FunctionModel function_model = FunctionModel::Standard;
  ModuleSettings module;
  uint32_t command_timeout_ms = 2000;        // EnDat command over Flatstream
  uint32_t flatstream_timeout_cycles = 200;  // per-sequence timeout
  // POWERLINK only: byte offset of this module's block in its CN's PRes / PReq payload
  // (0..1489); unset = the default packed layout (docs/powerlink.md §Process image).
  std::optional<uint16_t> pres_offset;
  std::optional<uint16_t> preq_offset;
};

// Simulated node (also the test peer): motion and encoder of each simulated axis.
struct SimAxisConfig {
  MotionProfile profile = MotionProfile::ConstantVelocity;
  double velocity_periods_per_s = 100.0;  // constant velocity
  double amplitude_periods = 1000.0;      // sine
  double frequency_hz = 0.5;              // sine
  uint32_t module_cycle_us = 100;         // the module's system tick (X2X cycle)
  std::string encoder_file;               // optional YAML description of the encoder memory
  uint8_t inject_error_info = 0;          // ErrorInfo bits present from power-up
};
struct SimulatedBusConfig {
  std::vector<SimAxisConfig> axes;  // one per configured axis; missing entries take defaults
};

// One object the MN writes to a CN by SDO in the boot step "configure" (little endian bytes).
struct CnObjectWrite {
  uint16_t index = 0;
  uint8_t subindex = 0;
  std::vector<uint8_t> data;
  bool from_cdc = false;  // from a concise DCF (else from the YAML `sdo_writes`)
  friend bool operator==(const CnObjectWrite&, const CnObjectWrite&) = default;
};

// POWERLINK Controlled Node as the MN sees it.
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
  bool cycle_objects = false;  // write 0x1006 and 0x1F98/4,5 from the configuration
  // PResTimeout (0x1F92/node): how long the MN waits for the PRes after the PReq. Long enough for
  // a CN that answers from software on a busy PC (docs/realtime.md); a lost PRes costs it once.
  uint32_t pres_timeout_us = 200;
  // DLL_MNCNLossPResThreshold (0x1C09/node); unset: powerlink.thresholds.loss_of_pres.
  std::optional<uint32_t> loss_of_pres_threshold;
  bool mandatory = true;
  uint32_t multiplex = 0;             // 0 = continuous, n = polled every n-th cycle
  std::optional<uint16_t> preq_size;  // default: from IdentResponse PollOutSize / module list
  std::optional<uint16_t> pres_size;  // default: from IdentResponse PollInSize / module list
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
  uint32_t pre_op1_timeout_ms = 500;     // reduced cycle before the MN starts full cycles
  uint32_t boot_step_timeout_ms = 5000;  // a CN stuck in a boot step is reset
  uint32_t reset_wait_ms = 100;          // after NMTResetNode, before identifying again
  uint32_t status_request_every = 8;     // cycles between StatusRequests to a booting CN
};

struct PowerlinkBusConfig {
  std::string interface;  // raw-socket interface, e.g. "eth1"
  std::string cdc;        // the MN's concise DCF (openCONFIGURATOR's mnobd.cdc), as given
  std::vector<PowerlinkNodeConfig> nodes;
  DllThresholds thresholds;
  PowerlinkNmtConfig nmt;
  // AsyncSlotTimeout (0x1F8A/2): wait for the invited ASnd after the SoA.
  uint32_t async_timeout_us = 100;
  // WaitSoCPReq (0x1F8A/1): pause between the SoC and the first PReq, for CNs that need time to
  // take the SoC (a software CN) before they can answer a PReq.
  uint32_t wait_soc_preq_us = 0;
  RxWait rx_wait = RxWait::Block;
  uint32_t rx_spin_us = 0;  // Block: poll the ring this long before blocking
  uint32_t sdo_timeout_ms = 500;
  // PosTime relation: PosTime = low 32 bits of (SoC RelativeTime µs + offset).
  int64_t nettime_offset_us = 0;
  // Register → (index, subindex) overrides; default scheme in docs/powerlink.md.
  std::map<uint16_t, std::pair<uint16_t, uint8_t>> sdo_overrides;
};

// CAN-I/O (function model 254). The datasheet fixes the byte offsets inside the CAN objects, not
// the identifiers, the acyclic transport or the SYNC: those are configurable, with defaults that
// are ASSUMPTIONS (docs/canio.md §Assumptions).
enum class CanIdScheme : uint8_t {
  CanopenPredefined,  // CiA 301 predefined connection set, analog PDOs from PDO2 (CiA 401)
  Explicit,           // canio.axes[i].input_ids / output_id
};
enum class CanAcyclicTransport : uint8_t {
  CanopenSdo,  // expedited SDO, 0x600 + node → 0x580 + node
  None,        // no acyclic access: an axis needing configuration is refused at start
};
// What the daemon does after writing a configuration register over SDO (docs/canio.md
// §Read-back policy).
enum class CanVerify : uint8_t {
  Readback,  // read it back; "cannot be read" aborts leave the write unverified, not failed
  None,      // write only; after a silence the module is always configured again
};
// One axis' objects on the bus (index = axes[i]).
struct CanioAxisConfig {
  uint8_t first_analog_slot = 1;         // the module's first of its 2 analog logical slots
  std::optional<uint32_t> input_ids[2];  // explicit: object 1 (position), object 2
  std::optional<uint32_t> output_id;     // explicit: the output object
};
// The resolved identifiers of one axis (config_canio.cpp canio_axis_ids()).
struct CanioAxisIds {
  uint32_t input[2] = {0, 0};
  uint32_t output = 0;
};
struct CanioBusConfig {
  std::string interface = "can0";
  // Checked against the interface at start (SocketCAN's bit rate is set with `ip link`).
  uint32_t bitrate = 500000;
  // Wait this long after the SYNC for this cycle's input objects. 0: derived from the bit budget
  // (canio_timing(): the cycle's frames with worst-case stuffing + one frame already on the wire
  // + node_reaction_us); a configured value below the wire time is refused.
  uint32_t response_timeout_us = 0;
  // ASSUMPTION: the bus controller queues its answers this long after the SYNC's end of frame.
  uint32_t node_reaction_us = 200;
  // Share of the cycle the bus may carry (cyclic worst case + the daemon's paced SDO traffic).
  double max_bus_load = 0.7;
  CanVerify verify = CanVerify::Readback;
  uint32_t input_timeout_ms = 20;  // no complete sample for this long: the node is silent
  bool little_endian = true;
  bool sync_enabled = true;
  uint32_t sync_id = 0x080;
  CanIdScheme identifiers = CanIdScheme::CanopenPredefined;
  std::vector<CanioAxisConfig> axes;  // one per configured axis (missing entries: defaults)
  CanAcyclicTransport acyclic = CanAcyclicTransport::CanopenSdo;
  uint32_t sdo_timeout_ms = 100;
  // The SDO worker starts at most one transfer this often (and at most one a cycle): the acyclic
  // share of the bus-load budget.
  uint32_t sdo_interval_us = 5000;
  // Register → (index, subindex) overrides of the default SDO scheme (same as POWERLINK's,
  // docs/powerlink.md §SDO mapping): the configured index addresses slot 1.
  std::map<uint16_t, std::pair<uint16_t, uint8_t>> sdo_overrides;
  // Test transport instead of SocketCAN: the cross-process virtual bus of this name
  // (docs/canio.md).
  std::string virtual_bus;
};

// The CAN-I/O cycle's time on the wire (config_canio.cpp): what the response window and the
// bus-load check are made of. `modules` = axes on the bus.
struct CanioTiming {
  int64_t wire_ns = 0;             // SYNC + every object + one 8-byte frame already on the wire,
                                   // worst-case stuffing: the earliest the last answer can be in
  int64_t reaction_ns = 0;         // node_reaction_us
  uint32_t window_us = 0;          // the response window in use (configured or derived)
  uint32_t derived_window_us = 0;  // wire + reaction, rounded up to µs
  uint32_t min_window_us = 0;      // wire time rounded up: a shorter window can never be whole
  int64_t cyclic_ns = 0;           // the cycle's own frames (SYNC + objects), worst case
  int64_t acyclic_ns = 0;          // the SDO worker's share a cycle: one transfer (2 frames) per
                                   // max(period, sdo_interval_us), averaged over the period
  double load = 0.0;               // (cyclic + acyclic) / period
};
[[nodiscard]] CanioTiming canio_timing(const CanioBusConfig& canio, std::size_t modules,
                                       uint32_t period_us);

// The identifiers of axis `axis` under `canio` (generator or explicit table); node from the axis.
[[nodiscard]] CanioAxisIds canio_axis_ids(const CanioBusConfig& canio, const AxisConfig& axis,
                                          std::size_t index);

struct ShmConfig {
  std::string name = "/ds1928d";  // POSIX shm object name (/dev/shm/ds1928d)
  uint32_t mode = 0640;           // owner rw, group read-only
  std::string group;              // optional group owner
};

struct SocketConfig {
  std::string path = "/run/ds1928d/control.sock";
  uint32_t mode = 0660;
  std::string group;
  std::string privileged_group = "ds1928-admin";  // may send commands that change the encoder
  uint32_t max_clients = 64;
  uint32_t max_request_bytes = 4096;
  uint32_t idle_timeout_ms = 60000;
  // Replies a client has not read yet: past this many bytes no more of its requests are read
  // (back-pressure), and a client that leaves them unread for reply_stall_timeout_ms is closed.
  uint32_t reply_buffer_bytes = 262144;
  uint32_t reply_stall_timeout_ms = 10000;
};

// The OpenMetrics endpoint (docs/operations.md "Metrics"). Localhost by default: the figures
// describe the machine, and the endpoint has no authentication of its own.
struct MetricsListen {
  std::string address;  // IPv4 or IPv6 literal
  uint16_t port = 0;    // 0: any free port (tests)
};
struct MetricsConfig {
  std::optional<MetricsListen> listen = MetricsListen{"127.0.0.1", 9928};  // nullopt: off
  uint32_t max_connections = 64;
  uint32_t timeout_ms = 5000;  // to receive a request, and again to send the response
};

// `ds1928ctl capture` (docs/operations.md): the fixed ring each captured link/port gets at start,
// and the limits of one capture.
struct CaptureConfig {
  uint32_t ring_frames = 4096;             // frames per link/port, power of two
  uint32_t max_duration_s = 3600;          // a capture ends after this long at the latest
  uint64_t max_bytes = 1024ULL * 1048576;  // ... or once this many bytes were written
};

struct CycleConfig {
  uint32_t period_us = 1000;
  int rt_priority = 80;  // SCHED_FIFO 1..99
  int cpu = -1;          // -1 = no affinity
  uint32_t spin_us = 0;  // busy-wait this long before the deadline (0 = off)
  bool hold_cpu_dma_latency = true;
  bool lock_memory = true;
};

struct DaemonConfig {
  std::string source_file;  // where it was loaded from (for messages)
  CycleConfig cycle;
  BusKind bus = BusKind::Simulated;
  SimulatedBusConfig simulated;
  PowerlinkBusConfig powerlink;
  CanioBusConfig canio;
  std::vector<AxisConfig> axes;
  ShmConfig shm;
  SocketConfig socket;
  MetricsConfig metrics;
  CaptureConfig capture;
  std::string log_level = "info";
};

}  // namespace ds1928
