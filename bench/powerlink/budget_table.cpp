// The POWERLINK cycle budget's two figures (powerlink/cycle_budget.hpp) for 1, 4, 8 and 16
// X20DS1928 CNs (one module each: a 9-byte PReq and a 23-byte PRes payload), every CN polled
// with PReq/PRes or every CN chained (PRC), at the defaults ds1928d takes: PRes latency 2 µs, PRes
// timeout 200 µs, AsyncSlotTimeout 100 µs, AsyncMTU 300 bytes, no WaitSoCPReq. Pure arithmetic:
// no wire, no timing; the table in docs/powerlink.md §Cycle budget is its output.
//
// Usage: pl_budget_table [PERIOD_US]   (default 1000)
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "powerlink/cycle_budget.hpp"

namespace pl = ds1928::powerlink;

int main(int argc, char** argv) {
  const double period = argc > 1 ? std::atof(argv[1]) : 1000.0;
  std::printf("| CNs | mode | nominal (µs) | worst case (µs) | at %.0f µs |\n", period);
  std::printf("|---|---|---|---|---|\n");
  for (const unsigned count : {1u, 4u, 8u, 16u}) {
    for (const bool prc : {false, true}) {
      std::vector<pl::BudgetNode> nodes;
      for (unsigned i = 1; i <= count; ++i)
        nodes.push_back({static_cast<uint8_t>(i), 9, 23, 200, 0, prc, 2});
      pl::BudgetNetwork net;
      // The PResMN carries the chained nodes' outputs, 9 bytes each; 36 fill a minimum frame.
      net.pres_mn_payload = static_cast<uint16_t>(prc && count * 9 > 36 ? count * 9 : 36);
      const double nominal = pl::cycle_budget(nodes, net, pl::BudgetCase::kNominal).total_us();
      const double worst = pl::cycle_budget(nodes, net, pl::BudgetCase::kWorst).total_us();
      const char* verdict = nominal > period ? "refused"
                            : worst > period ? "accepted, worst case warned"
                                             : "accepted";
      std::printf("| %u | %s | %.2f | %.2f | %s |\n", count, prc ? "PRC" : "PReq/PRes", nominal,
                  worst, verdict);
    }
  }
  return 0;
}
