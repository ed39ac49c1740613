// What the CAN-I/O driver is told about its bus: interface, bit rate, SYNC, identifiers, acyclic
// transport, timeouts (docs/canio.md), and the two facts derived from it that the configuration
// checks and the driver uses alike: the identifiers of an axis and the cycle's time on the wire.
// The configuration's `canio:` section fills it (src/config); the daemon builds the driver's
// CanioBusOptions from it (make_canio_options()).
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/axis_config.hpp"

namespace ds1928 {

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
// CiA 301 NMT master (docs/canio.md §NMT): Start: after configuring a node the daemon sends NMT
// Start to it (and Enter Pre-Operational at stop); None: for bus controllers that start by
// themselves, no NMT command is ever sent.
enum class CanNmt : uint8_t { Start, None };
// The identity a CANopen node must report (CiA 301: 0x1000 device type, 0x1018/1..4 identity
// object), checked by SDO before the node is started (docs/canio.md §Node identity). Unset:
// not read.
struct CanioExpectedIdentity {
  std::optional<uint32_t> device_type;   // 0x1000/0
  std::optional<uint32_t> vendor_id;     // 0x1018/1
  std::optional<uint32_t> product_code;  // 0x1018/2
  std::optional<uint32_t> revision_no;   // 0x1018/3
  std::optional<uint32_t> serial_no;     // 0x1018/4
  [[nodiscard]] bool any() const noexcept {
    return device_type || vendor_id || product_code || revision_no || serial_no;
  }
};
// One CANopen node on the bus (canio.nodes[]): its error control and identity.
struct CanioNodeOptions {
  uint8_t node = 1;
  // Heartbeat producer time written to the node's object 0x1017 (ms, 0: no heartbeat watched).
  uint32_t heartbeat_ms = 0;
  // Consumer timeout (ms); 0: 1.5 × heartbeat_ms (an ASSUMPTION, docs/canio.md).
  uint32_t heartbeat_timeout_ms = 0;
  CanioExpectedIdentity identity;
};
// One axis' objects on the bus (index = axes[i]).
struct CanioAxisConfig {
  uint8_t first_analog_slot = 1;         // the module's first of its 2 analog logical slots
  std::optional<uint32_t> input_ids[2];  // explicit: object 1 (position), object 2
  std::optional<uint32_t> output_id;     // explicit: the output object
};
// The resolved identifiers of one axis (canio_axis_ids()).
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
  // The bus loop starts at most one SDO transfer this often (and at most one a cycle): the acyclic
  // share of the bus-load budget.
  uint32_t sdo_interval_us = 5000;
  // The additional-information channels (axes[].info) are read by SDO (EnDatInfoOK, then each
  // configured EnDatInfo0N) once per this interval per axis, off the cycle's objects.
  uint32_t info_interval_ms = 1000;
  // Register → (index, subindex) overrides of the default SDO scheme (same as POWERLINK's,
  // docs/powerlink.md §SDO mapping): the configured index addresses slot 1.
  std::map<uint16_t, std::pair<uint16_t, uint8_t>> sdo_overrides;
  CanNmt nmt = CanNmt::Start;
  std::vector<CanioNodeOptions> nodes;  // error control per node (nodes without entry: none)
  // Repeated samples (PosCycle unchanged) published before the axis goes stale; 0: derived from
  // the EnDat cycle and the period (stall_limit_cycles()).
  uint32_t stall_limit = 0;
  // restart-ms 0 on the interface (a bus-off is permanent until `ip link … restart`) is refused
  // at start unless this is true.
  bool allow_manual_restart = false;
  // Test transport instead of SocketCAN: the cross-process virtual bus of this name
  // (docs/canio.md).
  std::string virtual_bus;
};

// The CAN-I/O cycle's time on the wire: what the response window and the
// bus-load check are made of. `modules` = axes on the bus.
struct CanioTiming {
  int64_t wire_ns = 0;             // SYNC + every object + one 8-byte frame already on the wire,
                                   // worst-case stuffing: the earliest the last answer can be in
  int64_t reaction_ns = 0;         // node_reaction_us
  uint32_t window_us = 0;          // the response window in use (configured or derived)
  uint32_t derived_window_us = 0;  // wire + reaction, rounded up to µs
  uint32_t min_window_us = 0;      // wire time rounded up: a shorter window can never be whole
  uint32_t after_window_us = 0;    // an SDO request and its answer after the window (worst case)
  int64_t cyclic_ns = 0;           // the cycle's own frames (SYNC + objects), worst case
  int64_t acyclic_ns = 0;          // the SDO transfers' share a cycle: one transfer (2 frames) per
                                   // max(period, sdo_interval_us), averaged over the period
  double load = 0.0;               // (cyclic + acyclic) / period
};
[[nodiscard]] CanioTiming canio_timing(const CanioBusConfig& canio, std::size_t modules,
                                       uint32_t period_us);

// How many repeated samples (the same PosCycle, or under POWERLINK the same PosTime) in a row an
// axis may publish before it is stale: a module delivers a new position every EnDat cycle
// (module cycle × prescaler; the module cycle is at most 200 µs, datasheet: prescaler 2 →
// 200–400 µs), so after twice the longest EnDat cycle plus one bus cycle without a new position
// the acquisition has stalled. `configured` > 0 wins.
[[nodiscard]] constexpr uint32_t stall_limit_cycles(uint32_t configured, uint16_t prescaler,
                                                    uint32_t period_us) noexcept {
  if (configured != 0) return configured;
  if (period_us == 0) return 2;
  const uint64_t endat_max_us = uint64_t{prescaler == 0 ? 1u : prescaler} * 200;
  return static_cast<uint32_t>((2 * endat_max_us + period_us - 1) / period_us) + 1;
}

// The node's error-control options (defaults when canio.nodes has no entry for it).
[[nodiscard]] CanioNodeOptions canio_node_options(const CanioBusConfig& canio, uint8_t node);

// The identifiers of axis `axis` under `canio` (generator or explicit table); node from the axis.
[[nodiscard]] CanioAxisIds canio_axis_ids(const CanioBusConfig& canio, const AxisConfig& axis,
                                          std::size_t index);

}  // namespace ds1928
