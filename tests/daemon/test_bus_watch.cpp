// BusWatch: the log lines that explain gaps in the positions — bus state changes and nodes the
// POWERLINK MN reset (with the reason) or booted — from a real PowerlinkBus over an in-memory CN.
#include <catch2/catch.hpp>

#include "daemon.hpp"
#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"

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
  CHECK(watch.poll(*rig.bus).empty());  // the first look is the baseline
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  auto events = watch.poll(*rig.bus);
  INFO(joined(events));
  REQUIRE(events.size() == 2);
  CHECK_FALSE(events[0].warning);
  CHECK(events[0].text == "bus powerlink: booting -> operational");
  CHECK(events[1].text == "powerlink node 1: operational (boot 1)");
  CHECK(watch.poll(*rig.bus).empty());  // nothing new, nothing said

  rig.cns[0]->drop_pres = true;  // two lost PRes in a row reach the default threshold
  rig.step();
  rig.step();
  rig.cns[0]->drop_pres = false;
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
