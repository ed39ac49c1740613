// The expected topology on POWERLINK: of two CNs (each with one X20DS1928), node 2 is not the
// expected product. The MN does not boot it (IdentResponse against powerlink.nodes[].product_code)
// and exactly its axis stays down while node 1's axis delivers; `topology` marks node 2 with the
// reason. A real PowerlinkBus over in-memory CNs (tests/powerlink/test_cn.cpp). The module state
// like the r-LED: node 1's module runs, node 2's (refused) stays pre-operational; with RD = 0 from
// node 1 its module leaves RUN for PREOP once its data stops for the arrival window, and returns.
#include <catch2/catch.hpp>

#include "cycle_work.hpp"
#include "mn_rig.hpp"
#include "module_leds.hpp"
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

  // The module state, from the cycles the cycle work runs itself on the same bus.
  const auto run_cycles = [&](int n) {
    for (int i = 0; i < n; ++i) {
      CycleContext ctx;
      ctx.index = rig.cycle;
      ctx.start_ns = static_cast<int64_t>(rig.cycle) * test::kPeriodNs;
      ctx.woke_ns = ctx.start_ns;
      test::g_clock_ns = ctx.start_ns;
      work.run_cycle(ctx);
      ++rig.cycle;
    }
  };
  run_cycles(10);
  CHECK(service.node_phase(0) == NodePhase::Operational);
  // Refused for its identity, node 2 still answers: it reports PRE_OPERATIONAL_2 (it took the
  // SoCs meant for node 1), and its module is not started.
  CHECK(service.node_phase(1) == NodePhase::PreOp);
  const ModuleLeds m0 = module_leds(service, work, dc, 0);
  CHECK(m0.state == ModuleState::Run);
  CHECK(m0.error_class == ModuleErrorClass::None);
  CHECK(module_leds(service, work, dc, 1).state == ModuleState::PreOp);
  nlohmann::json a0;
  add_module_leds(a0, m0);
  CHECK(a0["module_state"] == "run");
  CHECK(a0["module_error_class"] == "none");
  CHECK(a0["module"]["r_led"] == "on");
  CHECK(a0["module"]["e_led"] == "off");
  metrics::Exposition out(metrics::Format::Prometheus);
  append_module_metrics(out, service, work, dc);
  const std::string text = out.finish();
  CHECK(text.find("ds1928_axis_module_state{axis=\"0\",name=\"" + dc.axes[0].name +
                  "\",state=\"run\"} 1") != std::string::npos);
  CHECK(text.find("ds1928_axis_module_state{axis=\"1\",name=\"" + dc.axes[1].name +
                  "\",state=\"preop\"} 1") != std::string::npos);
  CHECK(text.find("ds1928_axis_module_error_class{axis=\"0\",name=\"" + dc.axes[0].name +
                  "\",class=\"none\"} 1") != std::string::npos);

  // Node 1 stays OPERATIONAL but its PRes say RD = 0: its data no longer arrives. Within the
  // arrival window the module still counts as running; after it, PREOP.
  rig.cns[0]->pres_not_ready = true;
  run_cycles(50);
  CHECK(module_leds(service, work, dc, 0).state == ModuleState::Run);
  run_cycles(static_cast<int>(kArrivalWindowNs / test::kPeriodNs));
  CHECK(service.node_phase(0) == NodePhase::Operational);
  CHECK(module_leds(service, work, dc, 0).state == ModuleState::PreOp);
  rig.cns[0]->pres_not_ready = false;
  run_cycles(5);
  CHECK(module_leds(service, work, dc, 0).state == ModuleState::Run);
}
