// BusWatch: the log lines that explain gaps in the positions — bus state changes and nodes the
// POWERLINK MN reset (with the reason) or booted — from a real PowerlinkBus over an in-memory CN.
#include <catch2/catch.hpp>

#include "daemon.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "test_cn.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;

namespace {

int64_t g_now_ns = 0;
int64_t test_clock() noexcept {
  return g_now_ns;
}

struct Rig {
  MnConfig config;
  test::MemoryLink link;
  std::unique_ptr<test::TestCn> cn;
  std::unique_ptr<PowerlinkBus> bus;
  std::vector<AxisIo> axes;
  uint64_t cycle = 0;

  Rig() {
    g_now_ns = 0;
    config.cycle_us = 1000;
    config.mac = link.mac();
    PowerlinkNodeConfig nc;
    nc.node_id = 1;
    config.bus.nodes.push_back(nc);
    AxisConfig a;
    a.node = 1;
    a.slot = 1;
    config.axes.push_back(a);
    const std::vector<ModuleSpec> specs{
        {a.slot, a.module.input_mtu, a.module.output_mtu, a.pres_offset, a.preq_offset}};
    auto layout = make_layout(specs);
    REQUIRE(layout);
    cn = std::make_unique<test::TestCn>(1, *layout);
    link.cns.push_back(cn.get());
    bus = std::make_unique<PowerlinkBus>(config, link);
    bus->set_clock(&test_clock);
    axes.resize(1);
    REQUIRE_FALSE(bus->start());
  }
  void step() {
    g_now_ns = static_cast<int64_t>(cycle) * 1'000'000;
    (void)bus->exchange(axes, g_now_ns, cycle);
    ++cycle;
  }
  template <class P>
  bool run_until(P pred, int max = 5000) {
    for (int i = 0; i < max; ++i) {
      step();
      if (pred()) return true;
    }
    return false;
  }
};

std::string joined(const std::vector<BusEvent>& events) {
  std::string s;
  for (const auto& e : events) s += (e.warning ? "W " : "I ") + e.text + "\n";
  return s;
}

}  // namespace

TEST_CASE("BusWatch names state changes, resets with their reason and boots", "[daemon][log]") {
  Rig rig;
  BusWatch watch;
  CHECK(watch.poll(*rig.bus).empty());  // the first look is the baseline
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  auto events = watch.poll(*rig.bus);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK_FALSE(events[0].warning);
  CHECK(events[0].text == "bus powerlink: booting -> operational");
  CHECK(events[1].text == "powerlink node 1: operational (boot 1)");
  CHECK(watch.poll(*rig.bus).empty());  // nothing new, nothing said

  rig.cn->drop_pres = true;  // two lost PRes in a row reach the default threshold
  rig.step();
  rig.step();
  rig.cn->drop_pres = false;
  events = watch.poll(*rig.bus);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK(events[0].warning);
  CHECK(events[0].text == "bus powerlink: operational -> booting");
  CHECK(events[1].warning);
  CHECK(events[1].text ==
        "powerlink node 1: reset by the MN (loss of PRes threshold reached; resets 1, PRes losses "
        "2)");

  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  events = watch.poll(*rig.bus);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK(events[0].text == "bus powerlink: booting -> operational");
  CHECK(events[1].text == "powerlink node 1: operational (boot 2)");
}
