// The RD flag (EPSG DS 301 "ready"): a PRes with RD = 0 carries no valid inputs, and the MN's
// PReq says RD = 1 only for outputs it wrote in this cycle while OPERATIONAL.
#include <catch2/catch.hpp>

#include "mn_rig.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;
using test::Rig;

TEST_CASE("A PRes with RD = 0 is not taken as inputs, and is counted per CN",
          "[powerlink][mn][rd]") {
  Rig rig({1, 2}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->managing_node().all_operational(); }));
  rig.cns[0]->inputs.position_lw = 0x1000;
  rig.cns[1]->inputs.position_lw = 0x2000;
  rig.step();
  REQUIRE(rig.axes[0].inputs_fresh);
  REQUIRE(rig.axes[1].inputs_fresh);
  CHECK(rig.st(1).pres_ready);
  const uint32_t resets = rig.st(1).resets;

  // Node 1's application holds its data back: RD = 0 in OPERATIONAL, with new bytes in the PRes.
  rig.cns[0]->pres_not_ready = true;
  rig.cns[0]->inputs.position_lw = 0xDEAD;
  for (int i = 0; i < 100; ++i) {
    const ExchangeResult r = rig.step();
    CHECK(r.bus_up);
    CHECK_FALSE(rig.axes[0].inputs_fresh);
    CHECK(rig.axes[1].inputs_fresh);  // the other CN is not affected
  }
  CHECK(rig.axes[0].inputs.position_lw == 0x1000);  // its bytes never reached the axis
  CHECK(rig.st(1).pres_not_ready == 100);
  CHECK_FALSE(rig.st(1).pres_ready);
  CHECK(rig.st(2).pres_not_ready == 0);
  // Not a loss: the CN answers, stays OPERATIONAL and is not reset.
  CHECK(rig.st(1).loss_of_pres.events == 0);
  CHECK(rig.st(1).boot == CnBootState::kOperational);
  CHECK(rig.st(1).resets == resets);
  PresSnapshot snap;
  REQUIRE(rig.bus->pres_snapshot(1, snap));
  CHECK(snap.fresh);        // arrived ...
  CHECK_FALSE(snap.ready);  // ... but says its data is not ready

  rig.cns[0]->pres_not_ready = false;
  rig.step();
  CHECK(rig.axes[0].inputs_fresh);
  CHECK(rig.axes[0].inputs.position_lw == 0xDEAD);
  CHECK(rig.st(1).pres_ready);
}

TEST_CASE("The PReq says RD = 1 only when the MN wrote the whole output image while OPERATIONAL",
          "[powerlink][mn][rd]") {
  SECTION("outputs written: RD = 1 once OPERATIONAL") {
    Rig rig({1}, 1);
    rig.step();
    REQUIRE(rig.run_until([&] { return rig.st(1).in_isochronous; }));
    CHECK_FALSE(rig.cns[0]->last_preq_ready);  // not OPERATIONAL yet
    REQUIRE(rig.run_until([&] { return rig.bus->managing_node().all_operational(); }));
    rig.step();
    CHECK(rig.cns[0]->last_preq_ready);
  }
  SECTION("a PReq too short for the module's outputs: RD = 0 even when OPERATIONAL") {
    Rig rig({1}, 1);
    rig.cns[0]->poll_out_size = 2;  // the CN asks for 2 bytes; the module's outputs need more
    REQUIRE(rig.run_until([&] { return rig.bus->managing_node().all_operational(); }));
    for (int i = 0; i < 10; ++i) {
      rig.step();
      CHECK(rig.cns[0]->last_preq_payload.size() == 2);
      CHECK_FALSE(rig.cns[0]->last_preq_ready);
    }
  }
}
