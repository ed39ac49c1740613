// BusWatch: the log lines that explain gaps in the positions — bus state changes and nodes the
// POWERLINK MN reset (with the reason) or booted — from a real PowerlinkBus over an in-memory CN.
#include <fmt/format.h>

#include <catch2/catch.hpp>

#include "daemon.hpp"
#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "powerlink_service.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;

namespace {

using test::Rig;

std::string joined(const std::vector<BusEvent>& events) {
  std::string s;
  for (const auto& e : events) s += (e.warning ? "W " : "I ") + e.text + "\n";
  return s;
}

}  // namespace

TEST_CASE("BusWatch names state changes, resets with their reason and boots", "[daemon][log]") {
  Rig rig({1}, 1);
  BusWatch watch;
  PowerlinkService service(*rig.bus);
  CHECK(watch.poll(service).empty());  // the first look is the baseline
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  auto events = watch.poll(service);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK_FALSE(events[0].warning);
  CHECK(events[0].text == "bus powerlink: booting -> operational");
  CHECK(events[1].text == "powerlink node 1: operational (boot 1)");
  CHECK(watch.poll(service).empty());  // nothing new, nothing said

  rig.cns[0]->drop_pres = true;  // two lost PRes in a row reach the default threshold
  rig.step();
  rig.step();
  rig.cns[0]->drop_pres = false;
  events = watch.poll(service);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK(events[0].warning);
  // The state change names its cause: the CN that is not operational.
  CHECK(events[0].text.rfind("bus powerlink: operational -> booting: not yet operational: node 1 ",
                             0) == 0);
  CHECK(events[0].reason.rfind("not yet operational: node 1 ", 0) == 0);
  CHECK(events[1].warning);
  CHECK(events[1].text ==
        "powerlink node 1: reset by the MN (loss of PRes threshold reached; resets 1, PRes losses "
        "2)");

  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  events = watch.poll(service);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK(events[0].text == "bus powerlink: booting -> operational");
  CHECK(events[1].text == "powerlink node 1: operational (boot 2)");
}

TEST_CASE("BusWatch says counting-only thresholds at most once a second, with the count",
          "[daemon][log]") {
  Rig rig({1}, 1);
  BusWatch watch;
  PowerlinkService service(*rig.bus);
  const auto t0 = std::chrono::steady_clock::now();
  (void)watch.poll(service, t0);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  (void)watch.poll(service, t0);  // the boot's lines

  // Every clock read inside the exchange advances 300 µs: each cycle's exchange outlasts the
  // 1 ms period, the counter (+8, threshold 15) fires every second cycle.
  test::g_clock_step_ns = 300'000;
  for (int i = 0; i < 20; ++i) rig.step();
  const uint32_t fired_first = rig.bus->status().counters.cycle_time_exceeded.fired;
  REQUIRE(fired_first >= 5);
  auto events = watch.poll(service, t0 + std::chrono::milliseconds(10));
  INFO(joined(events));
  REQUIRE(events.size() == 1);
  CHECK(events[0].warning);
  CHECK(events[0].text ==
        fmt::format("powerlink: cycle time exceeded threshold reached {} time(s) (a cycle's "
                    "exchange took longer than the period; {} in total)",
                    fired_first, fired_first));

  for (int i = 0; i < 20; ++i) rig.step();
  CHECK(watch.poll(service, t0 + std::chrono::milliseconds(500)).empty());  // too soon
  const uint32_t fired_second = rig.bus->status().counters.cycle_time_exceeded.fired;
  REQUIRE(fired_second > fired_first);
  events = watch.poll(service, t0 + std::chrono::milliseconds(1100));
  INFO(joined(events));
  REQUIRE(events.size() == 1);
  CHECK_THAT(events[0].text,
             Catch::StartsWith(fmt::format("powerlink: cycle time exceeded threshold reached {} ",
                                           fired_second - fired_first)));
  test::g_clock_step_ns = 0;
  for (int i = 0; i < 20; ++i) rig.step();
  CHECK(watch.poll(service, t0 + std::chrono::seconds(5)).empty());  // nothing new: silent
}
