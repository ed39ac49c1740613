// The expected topology on POWERLINK: of two CNs (each with one X20DS1928), node 2 is not the
// expected product. The MN does not boot it (IdentResponse against powerlink.nodes[].product_code)
// and exactly its axis stays down while node 1's axis delivers; `topology` marks node 2 with the
// reason. A real PowerlinkBus over in-memory CNs (tests/powerlink/test_cn.cpp).
#include <catch2/catch.hpp>

#include "cycle_work.hpp"
#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "powerlink_service.hpp"
#include "topology.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;

TEST_CASE("topology: a wrong product on a CN keeps exactly that node's axis down",
          "[daemon][topology][powerlink]") {
  test::Rig rig({1, 2}, 1, {}, [](PowerlinkNodeConfig& n) {
    n.mandatory = n.node_id != 2;  // a mismatched optional CN must not stop the others
    if (n.node_id == 2) n.product_code = 0x1234;  // the test CN answers another product
  });
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  uint64_t fresh0 = 0, fresh1 = 0, up1 = 0;
  for (int i = 0; i < 500; ++i) {
    rig.step();
    fresh0 += rig.axes[0].inputs_fresh;
    fresh1 += rig.axes[1].inputs_fresh;
    up1 += rig.axes[1].axis_up && rig.axes[1].inputs_fresh;
  }
  CHECK(fresh0 > 400);  // node 1 delivers
  CHECK(fresh1 == 0);   // node 2 never
  CHECK(up1 == 0);
  CHECK(rig.st(2).boot == CnBootState::kIdentify);
  CHECK(rig.st(2).last_error == MnError::kIdentMismatch);

  // What `ds1928ctl topology` shows: node 2 with the expected product and the MN's reason.
  DaemonConfig dc;
  dc.bus = BusKind::Powerlink;
  dc.powerlink.nodes = rig.config.bus.nodes;
  dc.axes = rig.config.axes;
  dc.shm.name = "/unused";
  shm::Publisher publisher;  // not opened: the cycle work is only the topology's state holder
  CycleWork work(dc, *rig.bus, publisher);
  Topology topology(dc, work);
  PowerlinkService service(*rig.bus);
  const auto t = topology.topology_json(nullptr, service.status_json());
  REQUIRE(t["nodes"].size() == 2);
  CHECK(t["nodes"][0]["difference"].is_null());
  CHECK(t["nodes"][1]["expected"]["product_code"] == "0x00001234");
  REQUIRE_FALSE(t["nodes"][1]["difference"].is_null());
  CHECK(t["nodes"][1]["difference"].get<std::string>().find("identity") != std::string::npos);
}
