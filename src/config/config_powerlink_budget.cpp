// The POWERLINK cycle budget of a configuration and its check (docs/powerlink.md §Cycle budget).
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "config/config_powerlink.hpp"
#include "config/powerlink_budget.hpp"

namespace ds1928 {
namespace {

struct BudgetInputs {
  std::vector<powerlink::BudgetNode> nodes;
  std::vector<powerlink::PresMnNode> chained;  // placed: the PResMN's outputs
  std::size_t outputs_end = 0;                 // end of the chained nodes' outputs in the PResMN
};

BudgetInputs budget_inputs(const DaemonConfig& c) {
  BudgetInputs in;
  for (const PowerlinkNodeConfig& n : c.powerlink.nodes) {
    powerlink::BudgetNode b;
    b.node_id = n.node_id;
    b.pres_timeout_us = n.pres_timeout_us;
    b.pres_latency_us = n.pres_latency_us;
    b.multiplex_slot = n.multiplexed ? n.multiplex_slot.value_or(0) : uint8_t{0};
    b.prc = n.prc;
    if (n.prc)
      in.chained.push_back({n.node_id,
                            static_cast<uint16_t>(std::min<std::size_t>(
                                config_detail::output_image_size(c, n), 1490)),
                            0});
    std::size_t preq = 0, pres = 0;
    for (const AxisConfig& a : c.axes) {
      if (a.node != n.node_id) continue;
      preq += 2u + a.module.output_mtu;
      pres += 16u + a.module.input_mtu;
    }
    b.preq_payload = n.preq_size.value_or(static_cast<uint16_t>(std::min<std::size_t>(preq, 1490)));
    b.pres_payload = n.pres_size.value_or(static_cast<uint16_t>(std::min<std::size_t>(pres, 1490)));
    in.nodes.push_back(b);
  }
  in.outputs_end = powerlink::place_pres_mn_outputs(in.chained);
  return in;
}

PowerlinkCycleBudget budget_of(const DaemonConfig& c, const BudgetInputs& in) {
  powerlink::BudgetNetwork net;
  net.wait_soc_preq_us = c.powerlink.wait_soc_preq_us;
  net.async_slot_timeout_us = c.powerlink.async_timeout_us;
  net.async_mtu = c.powerlink.async_mtu;
  net.pres_mn_payload = static_cast<uint16_t>(
      std::min<std::size_t>(std::max<std::size_t>(c.powerlink.pres_mn_size, in.outputs_end), 1490));
  net.multiplex_cycles = c.powerlink.multiplex_cycles;
  PowerlinkCycleBudget b;
  b.period_us = c.cycle.period_us;
  b.nominal = powerlink::cycle_budget(in.nodes, net, powerlink::BudgetCase::kNominal);
  b.worst = powerlink::cycle_budget(in.nodes, net, powerlink::BudgetCase::kWorst);
  return b;
}

}  // namespace

PowerlinkCycleBudget powerlink_cycle_budget(const DaemonConfig& c) {
  return budget_of(c, budget_inputs(c));
}

std::string budget_terms(const powerlink::CycleBudget& b, uint16_t async_mtu) {
  const bool nominal = b.which == powerlink::BudgetCase::kNominal;
  char text[512];
  std::snprintf(text, sizeof text,
                "SoC %.1f, WaitSoCPReq %.1f, PRC slot of %zu node(s) %.1f, %zu PReq/PRes with "
                "their PRes %s %.1f, SoA %.1f + %s %.1f + ASnd of AsyncMTU %u bytes %.1f",
                b.soc_us, b.wait_soc_preq_us, b.prc_nodes, b.prc_us, b.polled_in_worst_cycle,
                nominal ? "latencies" : "timeouts", b.isochronous_us, b.soa_us,
                nominal ? "ASnd latency" : "AsyncSlotTimeout", b.async_wait_us, unsigned{async_mtu},
                b.asnd_us);
  return text;
}

std::string worst_case_warning(const PowerlinkCycleBudget& b, uint16_t async_mtu) {
  if (b.worst_fits()) return {};
  char text[256];
  std::snprintf(text, sizeof text,
                "the POWERLINK cycle fits cycle.period_us %u only while every CN answers in time: "
                "its worst case (every CN answering at its PRes timeout) takes %.1f us, %.1f us "
                "more (",
                b.period_us, b.worst.total_us(), b.worst.total_us() - b.period_us);
  return text + budget_terms(b.worst, async_mtu) +
         "); a late PRes then overruns the cycle (cycle_time_exceeded)";
}

namespace config_detail {

void check_cycle_budget(Diagnostics& diag, const DaemonConfig& c, const PowerlinkSites& sites) {
  const BudgetInputs in = budget_inputs(c);
  // The PResMN carries the chained nodes' outputs: pres_mn_size is at least their end.
  if (in.outputs_end > c.powerlink.pres_mn_size && sites.pres_mn_size_at) {
    std::string where;
    for (const auto& p : in.chained)
      where += (where.empty() ? "" : ", ") + std::string("node ") + std::to_string(p.node_id) +
               ": " + std::to_string(p.preq_size) + " bytes at " + std::to_string(p.base);
    diag.error(*sites.pres_mn_size_at, "powerlink.pres_mn_size",
               std::to_string(c.powerlink.pres_mn_size) +
                   " bytes cannot carry the outputs of the chained (prc) nodes, " +
                   std::to_string(in.outputs_end) + " bytes (" + where +
                   "); give at least that, or leave it out to have it derived");
  }
  if (in.outputs_end > 1490) {
    diag.error(sites.async_timeout_at, "powerlink",
               "the outputs of the chained (prc) nodes take " + std::to_string(in.outputs_end) +
                   " bytes, more than a PResMN carries (1490)");
    return;
  }
  const PowerlinkCycleBudget b = budget_of(c, in);
  if (b.nominal_fits()) return;
  char text[256];
  std::snprintf(text, sizeof text,
                "the POWERLINK cycle does not fit cycle.period_us %u: even with every CN "
                "answering in time (nominal) it takes %.1f us on the wire, %.1f us more (",
                c.cycle.period_us, b.nominal.total_us(), b.nominal.total_us() - b.period_us);
  diag.error(sites.async_timeout_at, "powerlink",
             text + budget_terms(b.nominal, c.powerlink.async_mtu) +
                 "); lengthen the period, poll fewer CNs per cycle (multiplexed), or lower "
                 "async_mtu / the nodes' pres_latency_us where they answer faster");
}

}  // namespace config_detail
}  // namespace ds1928
