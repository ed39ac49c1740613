// ds1928-sim canio: a simulated CAN-I/O bus controller with X20DS1928 modules in function model
// 254, on a SocketCAN interface (--iface) or on the cross-process virtual test bus (--virtual).
#include "canio_main.hpp"

#include <atomic>
#include <cstdio>
#include <memory>
#include <string>

#include "can/socketcan_port.hpp"
#include "can/virtual_bus.hpp"
#include "config/config_loader.hpp"
#include "core/clock.hpp"
#include "sim/canio_node.hpp"

namespace sim = ds1928::sim;
namespace canio = ds1928::canio;

int run_canio(const CanioOptions& o, const std::atomic<bool>& stop, std::atomic<bool>& reset) {
  sim::CanioNodeConfig node;
  uint32_t bitrate = o.bitrate;
  uint32_t period_us = 2000;
  if (!o.config_file.empty()) {
    auto loaded = ds1928::load_config(o.config_file);
    if (!loaded) {
      std::fprintf(stderr, "%s", loaded.error_report().c_str());
      return 1;
    }
    node = sim::canio_node_from_config(loaded.config().canio, loaded.config().axes,
                                       loaded.config().simulated, static_cast<uint8_t>(o.node));
    if (node.modules.empty()) {
      std::fprintf(stderr, "ds1928-sim: %s has no axis on node %d\n", o.config_file.c_str(),
                   o.node);
      return 1;
    }
    if (bitrate == 0) bitrate = loaded.config().canio.bitrate;
    period_us = loaded.config().cycle.period_us;
  } else {
    ds1928::DaemonConfig c;
    c.bus = ds1928::BusKind::Canio;
    c.canio.little_endian = o.byte_order == "little";
    c.canio.sync_enabled = !o.no_sync;
    c.canio.sync_id = o.sync_id;
    for (int m = 0; m < o.modules; ++m) {
      ds1928::AxisConfig a;
      a.node = static_cast<uint8_t>(o.node);
      a.slot = static_cast<uint8_t>(m + 1);
      a.function_model = ds1928::FunctionModel::BusController;
      c.axes.push_back(a);
      ds1928::CanioAxisConfig ca;
      ca.first_analog_slot = static_cast<uint8_t>(1 + 2 * m);
      c.canio.axes.push_back(ca);
    }
    c.simulated.axes.resize(c.axes.size());
    node = sim::canio_node_from_config(c.canio, c.axes, c.simulated, static_cast<uint8_t>(o.node));
  }
  node.faults.drop = o.drop;
  node.faults.wrong_length_every = o.wrong_length_every;
  node.faults.unexpected_id = o.unexpected_id;
  node.faults.answer_sdo = !o.no_sdo;
  node.faults.seed = o.seed;
  node.faults.late_object2 = o.late_object2;
  node.faults.late_object2_ns =
      int64_t{o.late_object2_us != 0 ? o.late_object2_us : period_us} * 1000;
  node.sync_reaction_ns = int64_t{o.sync_reaction_us} * 1000;
  node.self_start = o.self_start;
  node.heartbeat_ms = static_cast<uint16_t>(o.heartbeat_ms);
  node.faults.config_write_only = !o.config_readable;
  if (o.device_type >= 0) node.identity.device_type = static_cast<uint32_t>(o.device_type);
  if (o.vendor_id >= 0) node.identity.vendor_id = static_cast<uint32_t>(o.vendor_id);
  if (o.product_code >= 0) node.identity.product_code = static_cast<uint32_t>(o.product_code);
  if (o.revision_no >= 0) node.identity.revision_no = static_cast<uint32_t>(o.revision_no);
  if (o.serial_no >= 0) node.identity.serial_no = static_cast<uint32_t>(o.serial_no);
  node.identity.present = !o.no_identity;

  std::shared_ptr<canio::VirtualCanBus> vbus;
  std::unique_ptr<canio::CanPort> port;
  if (!o.virtual_bus.empty()) {
    auto bus = canio::VirtualCanBus::open_shared(
        o.virtual_bus, canio::virtual_bus_options(bitrate == 0 ? 500'000 : bitrate));
    if (!bus) {
      std::fprintf(stderr, "ds1928-sim: virtual bus '%s': %s\n", o.virtual_bus.c_str(),
                   canio::VirtualCanBus::open_error_text(o.virtual_bus, bus.error()).c_str());
      return 2;
    }
    vbus = bus.value();
    canio::VirtualPortOptions po;
    po.name = o.virtual_bus;
    po.bitrate = bitrate == 0 ? 500'000 : bitrate;
    auto p = vbus->open_port(po);
    if (!p) {
      std::fprintf(stderr, "ds1928-sim: virtual bus '%s': %s\n", o.virtual_bus.c_str(),
                   p.error().message().c_str());
      return 2;
    }
    port = std::move(p.value());
  } else {
    canio::SocketCanOptions so;
    so.interface = o.iface;
    so.expected_bitrate = bitrate;
    auto opened = canio::SocketCanPort::open(so);
    if (!opened.port) {
      std::fprintf(
          stderr, "ds1928-sim: %s\n",
          opened.message.empty() ? opened.error.message().c_str() : opened.message.c_str());
      return 2;
    }
    port = std::move(opened.port);
  }

  sim::CanioNode n(node, *port);
  std::FILE* answer_log = nullptr;
  if (!o.answer_log.empty()) {
    answer_log = std::fopen(o.answer_log.c_str(), "w");
    if (answer_log == nullptr) {
      std::fprintf(stderr, "ds1928-sim: --answer-log %s: cannot open\n", o.answer_log.c_str());
      return 2;
    }
    setvbuf(answer_log, nullptr, _IOLBF, 0);  // readable while the node runs
    // What the node sent for each SYNC it answered: the reference a test compares published
    // samples with (a sample is whole only if position and PosCycle come from one line).
    n.on_answer = [answer_log, &node](uint64_t sync, std::size_t m,
                                      const ds1928::ModuleInputs& in) {
      std::fprintf(
          answer_log, "%llu %u %llu %d\n", static_cast<unsigned long long>(sync),
          node.modules[m].slot,
          static_cast<unsigned long long>((uint64_t{in.position_hw} << 32) | in.position_lw),
          static_cast<int>(in.pos_cycle));
    };
  }
  if (auto ec = n.open()) {
    std::fprintf(stderr, "ds1928-sim: CAN filters on %s: %s\n", std::string(port->name()).c_str(),
                 ec.message().c_str());
    return 2;
  }
  std::printf("canio node %d: %zu module(s) on %s (%s), SYNC %s", o.node, n.module_count(),
              std::string(port->name()).c_str(), vbus ? "virtual bus" : "socketcan",
              node.sync_enabled ? "" : "off");
  if (node.sync_enabled) std::printf("0x%03X", node.sync_id);
  for (const auto& m : node.modules)
    std::printf(", slot %u: in 0x%03X/0x%03X out 0x%03X", m.slot, m.ids.input[0], m.ids.input[1],
                m.ids.output);
  std::printf(", SDO 0x%03X/0x%03X\n", 0x600 + o.node, 0x580 + o.node);
  std::fflush(stdout);

  const int64_t start = ds1928::rt::now_ns();
  const int64_t stop_at = o.duration_s > 0 ? start + static_cast<int64_t>(o.duration_s * 1e9) : 0;
  const int64_t silent_at =
      o.silent_after_s > 0 ? start + static_cast<int64_t>(o.silent_after_s * 1e9) : 0;
  const int64_t silent_until = silent_at + static_cast<int64_t>(o.silent_for_ms) * 1'000'000;
  auto at = [start](double s) { return s > 0 ? start + static_cast<int64_t>(s * 1e9) : 0; };
  int64_t reset_at = at(o.reset_after_s);
  int64_t emcy_at = at(o.emcy_after_s);
  const int64_t stall_at = at(o.stall_after_s);
  const int64_t stall_until = stall_at + static_cast<int64_t>(o.stall_for_ms) * 1'000'000;
  bool was_stalled = false;
  auto say = [start](int64_t now, const char* what) {
    std::printf("%10.6f node %s\n", static_cast<double>(now - start) / 1e9, what);
    std::fflush(stdout);
  };
  bool was_silent = false;
  while (!stop.load(std::memory_order_relaxed)) {
    (void)n.service(ds1928::rt::now_ns() + 20'000'000);
    const int64_t now = ds1928::rt::now_ns();
    const bool silent =
        silent_at != 0 && now >= silent_at && (o.silent_for_ms == 0 || now < silent_until);
    if (silent != was_silent) {
      was_silent = silent;
      if (!silent && o.power_cycle_when_back) n.power_up();
      n.set_silent(silent);
      std::printf("%10.6f node %s\n", static_cast<double>(now - start) / 1e9,
                  silent ? "silent" : "answering again");
      std::fflush(stdout);
    }
    if ((reset_at != 0 && now >= reset_at) || reset.exchange(false)) {
      reset_at = 0;
      n.request_reset();
      say(now, "resets by itself (brown-out: boot-up, pre-operational, settings lost)");
    }
    if (emcy_at != 0 && now >= emcy_at) {
      emcy_at = 0;
      n.request_emcy(static_cast<uint16_t>(o.emcy_code), 0x81, {0, 0, 0, 0, 0});
      say(now, "sends EMCY");
    }
    const bool stalled =
        stall_at != 0 && now >= stall_at && (o.stall_for_ms == 0 || now < stall_until);
    if (stalled != was_stalled) {
      was_stalled = stalled;
      n.set_stalled(stalled);
      say(now, stalled ? "acquisition stalled" : "acquisition running again");
    }
    if (stop_at != 0 && now >= stop_at) break;
  }
  if (answer_log) std::fclose(answer_log);
  const auto& c = n.counters();
  std::printf(
      "canio node %d stats: sync=%llu outputs=%llu inputs_sent=%llu dropped=%llu sdo=%llu "
      "sdo_aborts=%llu send_failures=%llu late_object2=%llu nmt=%llu boot_ups=%llu "
      "heartbeats=%llu emcy=%llu not_operational=%llu stalled=%llu\n",
      o.node, static_cast<unsigned long long>(c.syncs), static_cast<unsigned long long>(c.outputs),
      static_cast<unsigned long long>(c.inputs_sent),
      static_cast<unsigned long long>(c.inputs_dropped),
      static_cast<unsigned long long>(c.sdo_requests),
      static_cast<unsigned long long>(c.sdo_aborts),
      static_cast<unsigned long long>(c.send_failures),
      static_cast<unsigned long long>(c.inputs_late),
      static_cast<unsigned long long>(c.nmt_commands), static_cast<unsigned long long>(c.boot_ups),
      static_cast<unsigned long long>(c.heartbeats), static_cast<unsigned long long>(c.emcys),
      static_cast<unsigned long long>(c.ignored_not_operational),
      static_cast<unsigned long long>(c.stalled_answers));
  return 0;
}
