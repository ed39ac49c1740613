// The CAN-I/O bus' metric families (OpenMetrics endpoint): frames, controller state, bus-off,
// the planned cyclic bus load, per node samples (complete, half, missing, late) and SDO figures.
// Normal thread: reads the bus' atomics and its port counters, like `status`.
#include <string>
#include <vector>

#include "can/bit_budget.hpp"
#include "can/can_state.hpp"
#include "canio_service.hpp"

namespace ds1928 {

using metrics::Type;

void CanioService::append_metrics(metrics::Exposition& out) const {
  const canio::CanioBus& bus = *bus_;
  const auto& c = bus.counters();
  const canio::CanPortCounters pc = bus.port_counters();
  const std::string port(bus.port_name());
  const auto relaxed = [](const std::atomic<uint64_t>& a) {
    return a.load(std::memory_order_relaxed);
  };

  out.family("ds1928_canio_frames", Type::Counter,
             "CAN frames on the cycle port by direction (data and remote frames).");
  out.sample({{"interface", port}, {"direction", "rx"}}, pc.rx_frames);
  out.sample({{"interface", port}, {"direction", "tx"}}, pc.tx_frames);
  out.family("ds1928_canio_error_frames", Type::Counter, "CAN error frames received.");
  out.sample({{"interface", port}}, relaxed(c.error_frames));
  out.family("ds1928_canio_tx_dropped", Type::Counter,
             "Frames not sent: TX queue full, or bus-off / interface down / other errors.");
  out.sample({{"interface", port}, {"reason", "queue_full"}}, relaxed(c.tx_queue_full));
  out.sample({{"interface", port}, {"reason", "failed"}}, relaxed(c.tx_failed));
  out.family("ds1928_canio_rx_kernel_drops", Type::Counter,
             "Frames the kernel dropped for a full socket receive queue.");
  out.sample({{"interface", port}}, pc.rx_kernel_drops);
  out.family("ds1928_canio_unexpected_ids", Type::Counter,
             "Data frames with an identifier no configured axis uses.");
  out.sample({{"interface", port}}, relaxed(c.unexpected_ids));

  out.family("ds1928_canio_controller_state", Type::Gauge,
             "CAN controller state: 1 for the current state.");
  const canio::CanState state = bus.can_state();
  for (auto s : {canio::CanState::ErrorActive, canio::CanState::ErrorWarning,
                 canio::CanState::ErrorPassive, canio::CanState::BusOff, canio::CanState::Stopped,
                 canio::CanState::Sleeping, canio::CanState::Down, canio::CanState::Unknown})
    out.sample({{"interface", port}, {"state", canio::to_string(s)}},
               uint64_t{s == state ? 1u : 0u});
  out.family("ds1928_canio_bus_off", Type::Counter, "Bus-off events of the controller.");
  out.sample({{"interface", port}}, pc.bus_off_events);
  out.family("ds1928_canio_bus_off_cycles", Type::Counter,
             "Cycles skipped while the controller was bus-off or the interface down.");
  out.sample({{"interface", port}}, relaxed(c.bus_off_cycles));

  // The planned cyclic load: the configured frames per cycle at the bit rate against the period
  // (bit_budget.hpp). The measured rate follows from rate(ds1928_canio_frames_total).
  canio::CycleLoad load;
  load.modules = static_cast<uint32_t>(bus.options().axes.size());
  load.bitrate = bus.options().bus.bitrate;
  load.sync = bus.options().bus.sync_enabled;
  const canio::CycleFit fit =
      canio::check_cycle(load, static_cast<int64_t>(bus.options().period_us) * 1000);
  out.family("ds1928_canio_bus_load_ratio", Type::Gauge,
             "Planned share of the bus time the cyclic frames take (nominal and worst-case "
             "bit stuffing).");
  out.sample({{"interface", port}, {"estimate", "nominal"}}, fit.load_nominal);
  out.sample({{"interface", port}, {"estimate", "worst_case"}}, fit.load_worst_case);

  // Per CANopen node: its identity against canio.nodes[] (the expected topology).
  out.family("ds1928_canio_node_identity_mismatch", Type::Gauge,
             "1 while a CAN-I/O node's identity (0x1000 / 0x1018) differs from canio.nodes[] or "
             "cannot be read.");
  for (std::size_t k = 0; k < bus.node_count(); ++k) {
    const auto s = static_cast<canio::NodeIdentityState>(
        bus.node_counters(k).identity_state.load(std::memory_order_relaxed));
    out.sample({{"node", std::to_string(bus.node_counters(k).node)}},
               uint64_t{s == canio::NodeIdentityState::Mismatch ||
                                s == canio::NodeIdentityState::Unreadable
                            ? 1u
                            : 0u});
  }

  // Per node (one module per CAN-I/O node).
  const auto& axes = bus.options().axes;
  std::vector<std::string> node(axes.size()), axis(axes.size());
  for (std::size_t i = 0; i < axes.size(); ++i) {
    node[i] = std::to_string(axes[i].node);
    axis[i] = std::to_string(i);
  }
  const auto per_node = [&](std::string_view name, std::string_view help,
                            std::atomic<uint64_t> canio::CanioAxisCounters::*field) {
    out.family(name, Type::Counter, help);
    for (std::size_t i = 0; i < axes.size(); ++i)
      out.sample({{"node", node[i]}, {"axis", axis[i]}}, relaxed(bus.axis_counters(i).*field));
  };
  per_node("ds1928_canio_samples", "Cycles with both input objects of the node: complete sample.",
           &canio::CanioAxisCounters::samples);
  per_node("ds1928_canio_half_samples",
           "Cycles with only one of the two input objects: no sample published.",
           &canio::CanioAxisCounters::half_samples);
  per_node("ds1928_canio_missing_samples", "Cycles with neither input object.",
           &canio::CanioAxisCounters::missing);
  per_node("ds1928_canio_late_frames", "Input objects that arrived after their cycle.",
           &canio::CanioAxisCounters::late_frames);
  per_node("ds1928_canio_duplicate_frames",
           "Input objects seen twice in one cycle (sample dropped).",
           &canio::CanioAxisCounters::duplicates);
  per_node("ds1928_canio_unpaired_samples",
           "Both input objects there but not certainly answers to the same SYNC (sample dropped: "
           "a torn sample is never published).",
           &canio::CanioAxisCounters::unpaired);
  per_node("ds1928_canio_gated_samples",
           "Complete samples held back after a (re)configuration until PosCycle changed.",
           &canio::CanioAxisCounters::gated);
  per_node("ds1928_canio_unverified_writes",
           "Configuration writes whose read-back the module refused (left unverified).",
           &canio::CanioAxisCounters::unverified);
  per_node("ds1928_canio_rescans", "EnDatAck bit 1 (Rescan) written after enabling EnDat.",
           &canio::CanioAxisCounters::rescans);
  per_node("ds1928_canio_sdo_transfers", "Expedited SDO transfers to the node.",
           &canio::CanioAxisCounters::sdo_transfers);
  per_node("ds1928_canio_sdo_errors", "SDO transfers that failed (abort, timeout, mismatch).",
           &canio::CanioAxisCounters::sdo_errors);
  per_node("ds1928_canio_configurations", "Completed start-up configurations of the module.",
           &canio::CanioAxisCounters::configurations);
  per_node(
      "ds1928_canio_write_aborts",
      "Configuration writes the module refused with an SDO abort (reported, the rest written).",
      &canio::CanioAxisCounters::write_aborts);
  out.family("ds1928_canio_unconfigurable", Type::Gauge,
             "1 while a register the axis needs (EnDatMode, the Rescan) is refused: retried with "
             "back-off.");
  for (std::size_t i = 0; i < axes.size(); ++i)
    out.sample(
        {{"node", node[i]}, {"axis", axis[i]}},
        uint64_t{bus.axis_counters(i).unconfigurable.load(std::memory_order_relaxed) ? 1u : 0u});
  // Per CANopen node: NMT and error control (docs/canio.md §Node lifecycle).
  const auto per_canopen_node = [&](std::string_view name, std::string_view help,
                                    std::atomic<uint64_t> canio::CanioNodeCounters::*field) {
    out.family(name, Type::Counter, help);
    for (std::size_t k = 0; k < bus.node_count(); ++k)
      out.sample({{"node", std::to_string(bus.node_counters(k).node)}},
                 relaxed(bus.node_counters(k).*field));
  };
  per_canopen_node("ds1928_canio_nmt_starts", "NMT Start commands sent to the node.",
                   &canio::CanioNodeCounters::nmt_starts);
  per_canopen_node("ds1928_canio_nmt_start_retries",
                   "NMT Start repeated: the node stayed silent (or left OPERATIONAL) after it.",
                   &canio::CanioNodeCounters::start_retries);
  per_canopen_node("ds1928_canio_boot_ups",
                   "Boot-up messages: the node reset and was configured again.",
                   &canio::CanioNodeCounters::boot_ups);
  per_canopen_node("ds1928_canio_heartbeats", "Heartbeat messages received from the node.",
                   &canio::CanioNodeCounters::heartbeats);
  per_canopen_node("ds1928_canio_heartbeat_misses",
                   "Heartbeat consumer timeouts: the node's axes were taken down.",
                   &canio::CanioNodeCounters::heartbeat_misses);
  per_canopen_node("ds1928_canio_emcy", "EMCY (emergency) messages received from the node.",
                   &canio::CanioNodeCounters::emcys);
  out.family("ds1928_canio_node_silent", Type::Gauge,
             "1 while the node sent no complete sample for input_timeout_ms.");
  for (std::size_t i = 0; i < axes.size(); ++i)
    out.sample({{"node", node[i]}, {"axis", axis[i]}},
               uint64_t{bus.axis_counters(i).silent.load(std::memory_order_relaxed) ? 1u : 0u});
}

}  // namespace ds1928
