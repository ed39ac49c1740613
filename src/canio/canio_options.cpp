// The facts derived from the `canio` options that the configuration checks and the driver use
// alike: an axis' identifiers and the cycle's time on the wire (docs/canio.md).
#include "canio/canio_options.hpp"

#include <algorithm>

#include "can/bit_budget.hpp"

namespace ds1928 {

CanioAxisIds canio_axis_ids(const CanioBusConfig& canio, const AxisConfig& axis,
                            std::size_t index) {
  CanioAxisConfig a;
  if (index < canio.axes.size()) a = canio.axes[index];
  CanioAxisIds ids;
  if (canio.identifiers == CanIdScheme::Explicit) {
    ids.input[0] = a.input_ids[0].value_or(0);
    ids.input[1] = a.input_ids[1].value_or(0);
    ids.output = a.output_id.value_or(0);
    return ids;
  }
  // CiA 301 predefined set: TPDO k → 0x180 + 0x100·(k−1) + node, RPDO k → 0x200 + 0x100·(k−1) +
  // node. CiA 401 puts digital I/O in PDO1 and analog channels from PDO2 on: analog logical slot
  // s (8 bytes, one CAN object) → PDO s + 1. The module's input objects are its two slots; its
  // one output object is its first slot's RPDO.
  const uint32_t s = a.first_analog_slot;
  ids.input[0] = 0x180 + 0x100 * s + axis.node;
  ids.input[1] = 0x180 + 0x100 * (s + 1) + axis.node;
  ids.output = 0x200 + 0x100 * s + axis.node;
  return ids;
}

CanioNodeOptions canio_node_options(const CanioBusConfig& canio, uint8_t node) {
  for (const CanioNodeOptions& n : canio.nodes)
    if (n.node == node) return n;
  CanioNodeOptions n;
  n.node = node;
  return n;
}

CanioTiming canio_timing(const CanioBusConfig& canio, std::size_t modules, uint32_t period_us) {
  CanioTiming t;
  canio::CycleLoad load;
  load.modules = static_cast<uint32_t>(modules);
  load.bitrate = canio.bitrate;
  load.sync = canio.sync_enabled;
  const canio::CycleBudget cyclic = canio::cycle_budget(load);
  // One 8-byte frame (an SDO request or answer, or another node's object) may have started just
  // before the SYNC was queued: CAN does not preempt, so it delays everything by its length.
  canio::CycleLoad one;
  one.modules = 1;
  one.bitrate = canio.bitrate;
  one.input_frames_per_module = 1;
  one.output_frames_per_module = 0;
  const int64_t blocking_ns = canio::cycle_budget(one).time_worst_case_ns;
  t.cyclic_ns = cyclic.time_worst_case_ns;
  t.wire_ns = cyclic.time_worst_case_ns + blocking_ns;
  t.reaction_ns = int64_t{canio.node_reaction_us} * 1000;
  t.min_window_us = static_cast<uint32_t>((t.wire_ns + 999) / 1000);
  t.derived_window_us = static_cast<uint32_t>((t.wire_ns + t.reaction_ns + 999) / 1000);
  t.window_us = canio.response_timeout_us != 0 ? canio.response_timeout_us : t.derived_window_us;
  // The bus loop starts at most one SDO transfer per max(period, sdo_interval_us) and the node
  // answers it: two 8-byte frames, averaged over the cycle.
  if (canio.acyclic == CanAcyclicTransport::CanopenSdo && period_us > 0) {
    const int64_t interval_us = std::max<int64_t>(period_us, canio.sdo_interval_us);
    t.acyclic_ns = (2 * blocking_ns * period_us + interval_us - 1) / interval_us;
    // The transfer starts after the response window; request and answer must end before the
    // next SYNC.
    t.after_window_us = static_cast<uint32_t>((2 * blocking_ns + 999) / 1000);
  }
  if (period_us > 0)
    t.load = static_cast<double>(t.cyclic_ns + t.acyclic_ns) / (double(period_us) * 1000.0);
  return t;
}

}  // namespace ds1928
