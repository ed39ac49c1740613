// A CAN-I/O bus in one process for the driver tests: the daemon's CanioBus and simulated CAN-I/O
// nodes on one TIMED virtual bus (frames take their stuffed bit time at the configured bit rate,
// arbitration, RX stamps at end of frame). Two ways to run it:
//  - stepped (fake clock, one thread): the driver's port is wrapped so that every frame the
//    driver sends is served by the nodes at once; 10^5 cycles take seconds and every run is the
//    same run (seeded losses);
//  - threaded (real clock): the nodes serve their ports on their own thread, as the simulator
//    process does, and the driver configures the modules over SDO.
#pragma once

#include <algorithm>
#include <atomic>
#include <functional>
#include <limits>
#include <memory>
#include <thread>
#include <vector>

#include "can/virtual_bus.hpp"
#include "canio/canio_bus.hpp"
#include "config/config.hpp"
#include "sim/canio_node.hpp"

namespace ds1928::test {

inline std::atomic<int64_t> g_fake_ns{1'000'000'000};
inline int64_t fake_now() noexcept {
  return g_fake_ns.load(std::memory_order_relaxed);
}

// Forwards to a port and runs `after_send` after every send: the peer answers at once. With
// `advance` (stepped rig) a receive that finds nothing moves the fake clock to the next answer a
// node has queued (its SYNC reaction, a late object 2) up to the deadline: a discrete-event run
// in which every frame is stamped with the fake time it was sent at.
class SteppedPort final : public canio::CanPort {
 public:
  SteppedPort(canio::CanPort& inner, std::function<void()> after_send,
              std::function<bool(int64_t)> advance = {})
      : inner_(inner), after_send_(std::move(after_send)), advance_(std::move(advance)) {}
  canio::SendResult send(const canio::CanFrame& f) noexcept override {
    const canio::SendResult r = inner_.send(f);
    after_send_();
    return r;
  }
  canio::ReceiveResult receive(std::span<canio::CanFrame> frames,
                               int64_t deadline_ns) noexcept override {
    if (!advance_) return inner_.receive(frames, deadline_ns);
    for (;;) {
      (void)advance_(0);  // what is due by now goes out
      const canio::ReceiveResult r = inner_.receive(frames, 0);
      if (r.count > 0 || r.error) return r;
      if (!advance_(deadline_ns)) return r;
    }
  }
  [[nodiscard]] canio::CanState state() const noexcept override { return inner_.state(); }
  [[nodiscard]] canio::CanPortCounters counters() const noexcept override {
    return inner_.counters();
  }
  [[nodiscard]] std::error_code set_filters(
      std::span<const canio::CanIdFilter> ids) noexcept override {
    return inner_.set_filters(ids);
  }
  [[nodiscard]] std::error_code set_error_mask(uint32_t classes) noexcept override {
    return inner_.set_error_mask(classes);
  }
  [[nodiscard]] Result<canio::CanInterfaceInfo> query_interface() noexcept override {
    return inner_.query_interface();
  }
  [[nodiscard]] std::string_view name() const noexcept override { return inner_.name(); }

 private:
  canio::CanPort& inner_;
  std::function<void()> after_send_;
  std::function<bool(int64_t)> advance_;
};

// `nodes` CAN-I/O nodes (1..nodes) with one X20DS1928 each (analog slot 1, predefined ids).
inline DaemonConfig canio_config(int nodes, uint32_t period_us = 2000) {
  DaemonConfig c;
  c.bus = BusKind::Canio;
  c.cycle.period_us = period_us;
  c.canio.response_timeout_us = 0;  // derived from the bit budget
  c.canio.input_timeout_ms = 20;
  for (int n = 1; n <= nodes; ++n) {
    AxisConfig a;
    a.name = "axis" + std::to_string(n - 1);
    a.node = static_cast<uint8_t>(n);
    a.slot = 1;
    a.function_model = FunctionModel::BusController;
    a.module.output_mtu = 5;
    a.module.input_mtu = 5;
    c.axes.push_back(a);
    c.canio.axes.push_back({});
  }
  c.simulated.axes.resize(c.axes.size());
  return c;
}

// Timed (default): the timed virtual bus at canio.bitrate. Instant: frames arrive at once (tests
// whose configuration deliberately does not fit the wire, e.g. the allocation proof's 1 ms cycle).
enum class BusMode { Default, Timed, Instant };

struct Rig {
  // stepped: fake clock and synchronous nodes; else real clock and a node thread.
  using NodeTweak = std::function<void(sim::CanioNodeConfig&)>;
  // Wraps each of the driver's ports (the cycle port, then the SDO port: `sdo`) before CanioBus
  // gets it, as the daemon puts a capture point (capture::CapturingCanPort) around both.
  using PortWrap =
      std::function<std::unique_ptr<canio::CanPort>(std::unique_ptr<canio::CanPort>, bool sdo)>;
  Rig(const DaemonConfig& config, bool stepped, bool assume_configured, BusMode mode,
      PortWrap wrap = {})
      : Rig(config, stepped, assume_configured, NodeTweak{}, mode, std::move(wrap)) {}
  Rig(const DaemonConfig& config, bool stepped, bool assume_configured, NodeTweak tweak = {},
      BusMode mode = BusMode::Default, PortWrap wrap = {})
      : config(config), stepped(stepped) {
    if (stepped) g_fake_ns.store(kT0);  // every rig starts at the same fake time
    canio::VirtualBusOptions bo;
    if (stepped) bo.clock = [] { return fake_now(); };
    // The timed bus: frames take their stuffed bit time, arbitration, RX stamps at end of frame.
    bo.bitrate = mode == BusMode::Instant ? 0 : config.canio.bitrate;
    bus = canio::VirtualCanBus::create_local(bo);
    driver_port = open_port("daemon");
    for (const AxisConfig& a : config.axes) {
      bool have = false;
      for (auto& n : nodes) have |= n->config().node == a.node;
      if (have) continue;
      node_ports.push_back(open_port("node" + std::to_string(a.node)));
      sim::CanioNodeConfig nc =
          sim::canio_node_from_config(config.canio, config.axes, config.simulated, a.node);
      if (stepped) nc.clock = [] { return fake_now(); };
      // A driver that configures nothing sends no NMT either: such a rig's nodes start by
      // themselves (the strict CANopen node waits for NMT Start otherwise).
      if (assume_configured) nc.self_start = true;
      if (tweak) tweak(nc);
      nodes.push_back(std::make_unique<sim::CanioNode>(nc, *node_ports.back()));
      (void)nodes.back()->open();
      if (assume_configured)
        for (std::size_t m = 0; m < nodes.back()->module_count(); ++m)
          (void)sim::configure_module(nodes.back()->module(m), a.module);
    }
    canio::CanioBusOptions options =
        canio::make_canio_options(config.canio, config.axes, config.cycle.period_us);
    options.assume_configured = assume_configured;
    options.identity_refuse = config.topology.refuse;  // as the daemon tells the driver
    std::unique_ptr<canio::CanPort> cycle;
    if (stepped) {
      cycle = std::make_unique<SteppedPort>(
          *driver_port,
          [this] {
            for (auto& n : nodes) (void)n->service(0);
          },
          [this](int64_t deadline) { return advance(deadline); });
    } else {
      cycle = std::make_unique<SteppedPort>(*driver_port, [] {});
    }
    std::unique_ptr<canio::CanPort> sdo;
    if (!assume_configured) sdo = open_port("daemon-sdo");
    if (wrap) {
      cycle = wrap(std::move(cycle), false);
      if (sdo) sdo = wrap(std::move(sdo), true);
    }
    canio = std::make_unique<canio::CanioBus>(options, std::move(cycle), std::move(sdo));
    if (stepped) canio->set_clock(&fake_now);
    io.resize(config.axes.size());
    if (!stepped) {
      node_thread = std::thread([this] {
        while (!stop.load()) {
          for (auto& n : nodes) (void)n->service(monotonic() + 1'000'000);
        }
      });
    }
  }
  ~Rig() {
    stop.store(true);
    if (node_thread.joinable()) node_thread.join();
    canio->stop();
  }

  // Stepped: nodes send what is due; with a deadline ahead, the fake clock jumps to the next
  // queued answer (true) or to the deadline (false: nothing more before it).
  bool advance(int64_t deadline) {
    for (auto& n : nodes) (void)n->service(0);  // what reached them, what is due
    const int64_t now = fake_now();
    if (deadline <= now) return false;
    int64_t next = std::numeric_limits<int64_t>::max();
    for (auto& n : nodes) next = std::min(next, n->next_due_ns());
    // The frame on the wire ends (and the next one in the queues may start).
    if (bus->timed()) {
      const int64_t free_at = bus->wire_totals().bus_free_ns;
      if (free_at > now) next = std::min(next, free_at);
    }
    if (next <= deadline) {
      g_fake_ns.store(std::max(now, next));
      for (auto& n : nodes) (void)n->service(0);
      return true;
    }
    g_fake_ns.store(deadline);
    return false;
  }

  static int64_t monotonic() noexcept {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
  }

  std::unique_ptr<canio::VirtualCanPort> open_port(const std::string& name) {
    canio::VirtualPortOptions po;
    po.name = name;
    po.bitrate = config.canio.bitrate;
    auto p = bus->open_port(po);
    if (!p) throw std::runtime_error("virtual port: " + p.error().message());
    return std::move(p.value());
  }

  // One cycle; stepped: at fake time `t0 + cycle × period`.
  ExchangeResult cycle(uint64_t index) {
    if (stepped) {
      // Between cycles the nodes and the bus go on: late answers go out when they are due.
      const int64_t start = kT0 + static_cast<int64_t>(index) * config.cycle.period_us * 1000;
      if (start > fake_now() && index > 0)
        while (advance(start)) {
        }
      g_fake_ns.store(start);
    }
    return canio->exchange(io, stepped ? fake_now() : monotonic(), index);
  }

  static constexpr int64_t kT0 = 1'000'000'000;
  DaemonConfig config;
  bool stepped;
  std::shared_ptr<canio::VirtualCanBus> bus;
  std::unique_ptr<canio::VirtualCanPort> driver_port;
  std::vector<std::unique_ptr<canio::VirtualCanPort>> node_ports;
  std::vector<std::unique_ptr<sim::CanioNode>> nodes;
  std::unique_ptr<canio::CanioBus> canio;
  std::vector<AxisIo> io;
  std::atomic<bool> stop{false};
  std::thread node_thread;
};

}  // namespace ds1928::test
