// Register requests of a ds1928d client on POWERLINK: SDO transfers on the axis' CN, queued per
// CN and through the register path, every one answered exactly once.
#include <catch2/catch.hpp>
#include <vector>

#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;
using test::le;
using test::Rig;

TEST_CASE("Register requests become SDO transfers", "[powerlink][mn]") {
  Rig rig({1}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  RegisterRequest w{7, 0, reg::kEnDatAck, 1, true, 0x02};
  REQUIRE(rig.bus->submit(w));
  RegisterResult res;
  REQUIRE(rig.run_until([&] { return rig.bus->poll(res); }, 200));
  CHECK(res.tag == 7);
  CHECK_FALSE(res.error);
  CHECK(le(rig.cns[0]->objects[{0x2001, 0x0F}]) == 2);

  RegisterRequest rd{8, 0, reg::kSystemCyclePrescaler, 2, false, 0};
  REQUIRE(rig.bus->submit(rd));
  REQUIRE(rig.run_until([&] { return rig.bus->poll(res); }, 200));
  CHECK(res.tag == 8);
  CHECK_FALSE(res.error);
  CHECK(res.value == 4);

  RegisterRequest missing{9, 0, reg::kEnDatError, 2, false, 0};  // object not in the CN
  REQUIRE(rig.bus->submit(missing));
  REQUIRE(rig.run_until([&] { return rig.bus->poll(res); }, 200));
  CHECK(res.tag == 9);
  CHECK(res.error == make_sdo_abort_error(0x06020000));
  CHECK(rig.bus->state() == BusState::Operational);
}

TEST_CASE("A burst of register requests longer than the node's SDO queue waits, none fails",
          "[powerlink][mn]") {
  Rig rig({1}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // As many as the request queue takes (64): twice the MN's per-node SDO queue.
  uint32_t submitted = 0;
  while (
      rig.bus->submit(RegisterRequest{100 + submitted, 0, reg::kSystemCyclePrescaler, 2, false, 0}))
    ++submitted;
  REQUIRE(submitted == 64);
  std::vector<uint32_t> tags;
  RegisterResult res;
  REQUIRE(rig.run_until(
      [&] {
        while (rig.bus->poll(res)) {
          CHECK_FALSE(res.error);
          CHECK(res.value == 4);
          tags.push_back(res.tag);
        }
        return tags.size() == submitted;
      },
      5000));
  for (uint32_t i = 0; i < submitted; ++i) CHECK(tags[i] == 100 + i);  // served in order
}

TEST_CASE("Every register request accepted gets its result, however long results are not taken",
          "[powerlink][mn]") {
  // Five nodes could queue 5 × 32 SDO transfers in the MN; its results ring holds 64 and the
  // request path 64 more. Nobody takes a result for 400 cycles while requests keep coming: the
  // MN accepts a request only with a result slot reserved for it, so none is dropped.
  Rig rig({1, 2, 3, 4, 5}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  uint32_t submitted = 0;
  for (int c = 0; c < 400; ++c) {
    while (rig.bus->submit(RegisterRequest{1000 + submitted, static_cast<uint16_t>(submitted % 5),
                                           reg::kSystemCyclePrescaler, 2, false, 0}))
      ++submitted;
    rig.step();
  }
  REQUIRE(submitted >= 128);  // more than one ring and path hold: the point is reached
  std::vector<int> seen(submitted, 0);
  RegisterResult res;
  uint32_t results = 0;
  REQUIRE(rig.run_until(
      [&] {
        while (rig.bus->poll(res)) {
          REQUIRE(res.tag >= 1000);
          REQUIRE(res.tag < 1000 + submitted);
          CHECK_FALSE(res.error);
          ++seen[res.tag - 1000];
          ++results;
        }
        return results == submitted;
      },
      20000));
  for (uint32_t i = 0; i < submitted; ++i) CHECK(seen[i] == 1);
}
