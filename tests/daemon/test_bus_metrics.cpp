// The POWERLINK bus' metric families from a real PowerlinkBus over an in-memory CN: per node NMT
// state, PRes counters and the PRes latency histogram, whose samples are the PRes received.
#include <catch2/catch.hpp>
#include <string>

#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "powerlink_service.hpp"

using namespace ds1928;

namespace {

double value_of(const std::string& body, const std::string& series) {
  const auto at = body.find("\n" + series + " ");
  if (at == std::string::npos) return -1;
  return std::strtod(body.c_str() + at + series.size() + 2, nullptr);
}

std::string render(const PowerlinkService& service) {
  metrics::Exposition out(metrics::Format::Prometheus);
  service.append_metrics(out);
  return "\n" + out.finish();
}

}  // namespace

TEST_CASE("POWERLINK metrics: NMT state, PRes counters and latency per node", "[daemon][metrics]") {
  powerlink::test::Rig rig({1, 2}, 1);
  PowerlinkService service(*rig.bus);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // Each clock read inside the exchange advances 30 µs: PReq sent → PRes received is a fixed
  // number of reads, so every sample lands in one known bucket.
  powerlink::test::g_clock_step_ns = 30'000;
  for (int i = 0; i < 10; ++i) rig.step();
  powerlink::test::g_clock_step_ns = 0;
  rig.step();  // publish

  const std::string text = render(service);
  INFO(text);
  for (const std::string node : {"1", "2"}) {
    const auto st = rig.bus->status();
    const auto* cn = &st.nodes[node == "1" ? 0 : 1];
    REQUIRE(cn->node == std::stoi(node));
    CHECK(value_of(text, "ds1928_powerlink_cn_nmt_state{node=\"" + node +
                             "\",state=\"OPERATIONAL\"}") == 1);
    CHECK(value_of(text,
                   "ds1928_powerlink_cn_nmt_state{node=\"" + node + "\",state=\"STOPPED\"}") == 0);
    CHECK(value_of(text, "ds1928_powerlink_pres_received_total{node=\"" + node + "\"}") ==
          cn->pres_received);
    CHECK(value_of(text, "ds1928_powerlink_cn_boots_total{node=\"" + node + "\"}") == 1);
    // One latency sample per PRes received.
    CHECK(value_of(text, "ds1928_powerlink_pres_latency_seconds_count{node=\"" + node + "\"}") ==
          cn->pres_received);
    // The stepped cycles' samples are ≥ 30 µs: above the first bucket (10 µs).
    const double first = value_of(
        text, "ds1928_powerlink_pres_latency_seconds_bucket{node=\"" + node + "\",le=\"1e-05\"}");
    CHECK(first >= 0);
    CHECK(first <= cn->pres_received - 10);
  }
  CHECK(value_of(text, "ds1928_powerlink_pres_lost_total{node=\"1\"}") == 0);
  rig.cns[0]->drop_pres = true;
  rig.step();
  rig.cns[0]->drop_pres = false;
  rig.step();
  CHECK(value_of(render(service), "ds1928_powerlink_pres_lost_total{node=\"1\"}") == 1);

  // RD = 0 from an OPERATIONAL CN: counted, and status says why its axes get no inputs.
  rig.cns[0]->pres_not_ready = true;
  for (int i = 0; i < 3; ++i) rig.step();
  CHECK(value_of(render(service), "ds1928_powerlink_pres_not_ready_total{node=\"1\"}") == 3);
  CHECK(value_of(render(service), "ds1928_powerlink_pres_not_ready_total{node=\"2\"}") == 0);
  nlohmann::json j = service.status_json();
  CHECK(j["nodes"][0]["pres_not_ready"] == 3);
  CHECK(j["nodes"][0]["inputs"] == "pres_not_ready");
  CHECK(j["nodes"][1]["inputs"] == "taken");
  rig.cns[0]->pres_not_ready = false;
  rig.step();
  j = service.status_json();
  CHECK(j["nodes"][0]["inputs"] == "taken");
}

TEST_CASE("POWERLINK status and metrics: the cycle budget's two figures and the measured occupancy",
          "[daemon][metrics][budget]") {
  powerlink::test::Rig rig({1, 2}, 1);
  PowerlinkService service(*rig.bus);
  // Two CNs at 1 ms with a 500 µs PRes timeout: nominal 6.72 + 2 × 15.44 + 35.76 = 73.36 µs,
  // worst case 6.72 + 2 × 513.44 + 133.76 = 1167.36 µs, over the period.
  std::vector<powerlink::BudgetNode> nodes{{1, 0, 0, 500, 0, false, 2},
                                           {2, 0, 0, 500, 0, false, 2}};
  PowerlinkCycleBudget budget;
  budget.period_us = 1000;
  budget.nominal = powerlink::cycle_budget(nodes, {}, powerlink::BudgetCase::kNominal);
  budget.worst = powerlink::cycle_budget(nodes, {}, powerlink::BudgetCase::kWorst);
  service.set_cycle_budget(budget, 300);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // Each clock read inside the exchange advances 10 µs: the phases end a fixed number of reads
  // after the SoC's, so the occupancy is known and above 0.
  powerlink::test::g_clock_step_ns = 10'000;
  for (int i = 0; i < 20; ++i) rig.step();
  powerlink::test::g_clock_step_ns = 0;
  rig.step();

  const nlohmann::json j = service.status_json();
  INFO(j.dump(2));
  const auto& b = j["cycle_budget"];
  CHECK(b["period_us"] == 1000);
  CHECK(b["nominal"]["total_us"].get<double>() == Approx(73.36));
  CHECK(b["nominal"]["polled"] == 2);
  CHECK(b["nominal"]["asnd_us"].get<double>() == Approx(27.04));
  CHECK(b["worst_case"]["total_us"].get<double>() == Approx(1167.36));
  CHECK(b["worst_case_fits"] == false);
  CHECK_THAT(b["warning"].get<std::string>(), Catch::Contains("1167.4 us, 167.4 us more"));
  const auto& iso = j["cycle_occupancy"]["isochronous_end"];
  const auto& async = j["cycle_occupancy"]["async_end"];
  CHECK(iso["count"].get<uint64_t>() >= 20);
  CHECK(async["count"].get<uint64_t>() >= iso["count"].get<uint64_t>());
  // The stepped cycles: the last PRes comes tens of µs after the SoC, the async phase later.
  CHECK(iso["max_us"].get<double>() >= 20);
  CHECK(async["max_us"].get<double>() > iso["max_us"].get<double>());
  CHECK(iso["p50_us"].get<double>() <= iso["p99_us"].get<double>());
  CHECK(iso["p99_us"].get<double>() <= iso["max_us"].get<double>());

  const std::string text = render(service);
  INFO(text);
  CHECK(value_of(text, "ds1928_powerlink_cycle_budget_seconds{case=\"nominal\"}") ==
        Approx(73.36e-6));
  CHECK(value_of(text, "ds1928_powerlink_cycle_budget_seconds{case=\"worst\"}") ==
        Approx(1167.36e-6));
  CHECK(value_of(text, "ds1928_powerlink_cycle_budget_worst_fits") == 0);
}
