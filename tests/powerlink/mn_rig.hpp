// The MN test rig: a PowerlinkBus over the in-memory wire with TestCns, driven cycle by cycle on
// a simulated clock. Shared by the MN tests and the daemon's bus-event tests.
#pragma once

#include <catch2/catch.hpp>
#include <functional>
#include <memory>
#include <vector>

#include "powerlink/powerlink_bus.hpp"
#include "test_cn.hpp"

namespace ds1928::powerlink::test {

inline constexpr int64_t kPeriodNs = 1'000'000;

// The first 4 bytes of an object's value, little-endian.
inline uint32_t le(const std::vector<uint8_t>& v) {
  uint32_t x = 0;
  for (std::size_t i = 0; i < v.size() && i < 4; ++i) x |= static_cast<uint32_t>(v[i]) << (8 * i);
  return x;
}

// Simulated CLOCK_MONOTONIC. Rig::step() sets it to the nominal cycle start plus the cycle
// thread's wake-up latency; every read advances it by `g_clock_step_ns` (0: the exchange takes
// no time).
inline int64_t g_clock_ns = 0;
inline int64_t g_clock_step_ns = 0;
inline int64_t fake_clock() noexcept {
  g_clock_ns += g_clock_step_ns;
  return g_clock_ns;
}

struct Rig {
  MnConfig config;
  MemoryLink link;
  std::vector<std::unique_ptr<TestCn>> cns;
  std::unique_ptr<PowerlinkBus> bus;
  std::vector<AxisIo> axes;
  uint64_t cycle = 0;

  // `place`: per-axis changes (e.g. PRes/PReq offset overrides) before the CNs are built.
  // `node_cfg`: changes to each node's configuration (object writes, identity, ...).
  explicit Rig(std::vector<uint8_t> nodes = {1}, uint8_t modules_per_node = 1,
               const std::function<void(AxisConfig&)>& place = {},
               const std::function<void(PowerlinkNodeConfig&)>& node_cfg = {}) {
    g_clock_ns = 0;
    g_clock_step_ns = 0;
    config.cycle_us = 1000;
    config.mac = link.mac();
    // Listening for another MN first (MNWaitNotAct) has tests of its own; these start at once.
    config.bus.nmt.wait_not_active_ms = 0;
    // The standard's threshold (two losses in a row): tests count losses against it.
    config.bus.thresholds.loss_of_pres = 15;
    for (uint8_t n : nodes) {
      PowerlinkNodeConfig nc;
      nc.node_id = n;
      if (node_cfg) node_cfg(nc);
      config.bus.nodes.push_back(nc);
      for (uint8_t s = 1; s <= modules_per_node; ++s) {
        AxisConfig a;
        a.node = n;
        a.slot = s;
        a.module.prescaler = static_cast<uint16_t>(3 + s);
        if (place) place(a);
        config.axes.push_back(a);
      }
    }
    for (uint8_t n : nodes) {
      std::vector<ModuleSpec> specs;
      for (const auto& a : config.axes)
        if (a.node == n)
          specs.push_back(
              {a.slot, a.module.input_mtu, a.module.output_mtu, a.pres_offset, a.preq_offset});
      auto layout = make_layout(specs);
      REQUIRE(layout);
      cns.push_back(std::make_unique<TestCn>(n, *layout));
      link.cns.push_back(cns.back().get());
    }
    bus = std::make_unique<PowerlinkBus>(config, link);
    bus->set_clock(&fake_clock);
    axes.resize(config.axes.size());
    REQUIRE_FALSE(bus->start());
  }
  // A new MN for a changed `config` (bus-wide keys such as multiplex_cycles).
  void rebuild() {
    bus = std::make_unique<PowerlinkBus>(config, link);
    bus->set_clock(&fake_clock);
    REQUIRE_FALSE(bus->start());
  }

  // `wake_ns`: how late the cycle thread starts the exchange after the nominal cycle start.
  ExchangeResult step(int64_t wake_ns = 0) {
    const int64_t start = static_cast<int64_t>(cycle) * kPeriodNs;
    g_clock_ns = start + wake_ns;
    auto r = bus->exchange(axes, start, cycle);
    ++cycle;
    return r;
  }
  // Runs until `pred` holds; fails after `max` cycles.
  template <class P>
  bool run_until(P pred, int max = 5000) {
    for (int i = 0; i < max; ++i) {
      step();
      if (pred()) return true;
    }
    return false;
  }
  const CnStatus& st(uint8_t node) const { return *bus->managing_node().node(node); }
};

}  // namespace ds1928::powerlink::test
