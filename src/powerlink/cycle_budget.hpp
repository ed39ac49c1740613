// Does a POWERLINK cycle fit its period? The worst case on the wire at 100 Mbit/s (seed 001):
// SoC, WaitSoCPReq, then per polled CN its PReq, PResTimeout and PRes, then SoA and the
// asynchronous slot (AsyncSlotTimeout plus the longest ASnd). Multiplexed CNs (EPSG DS 301) count
// in the cycle of their slot of the multiplexed cycle; the worst cycle is what must fit. PRC nodes
// (PollResponse Chaining) take the PRC slot instead: the PResMN, each PRC node's PRes with an
// inter-frame gap before it (the propagation delay the MN assigns, at least that), and the
// longest PRes timeout among them (how long the MN waits past the last PRes time).
// Header-only and pure: the configuration check, the Managing Node and the benchmarks use it.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace ds1928::powerlink {

// A frame of `length` bytes (without FCS) on the wire: padded to 60, + FCS 4, preamble 8 and
// inter-frame gap 12 bytes, at 12.5 bytes/µs (a 60-byte frame: 6.72 µs, seed 001).
[[nodiscard]] constexpr double wire_time_us(std::size_t length) noexcept {
  return static_cast<double>(std::max<std::size_t>(length, 60) + 24) * 0.08;
}

struct BudgetNode {
  uint8_t node_id = 1;
  uint16_t preq_payload = 0;
  uint16_t pres_payload = 0;
  uint32_t pres_timeout_us = 0;
  uint8_t multiplex_slot = 0;  // 0 = every cycle, k = cycle k of each multiplexed cycle
  bool prc = false;            // PollResponse Chaining: in the PRC slot, not polled with PReq
};

struct CycleBudget {
  double soc_us = 0;
  double wait_soc_preq_us = 0;
  double prc_us = 0;  // PResMN + the PRC nodes' PRes + their longest PRes timeout (0: no PRC)
  std::size_t prc_nodes = 0;
  double isochronous_us = 0;  // PReq + PResTimeout + PRes of the CNs of the worst cycle
  std::size_t polled_in_worst_cycle = 0;
  double async_us = 0;  // SoA + AsyncSlotTimeout + longest ASnd (1514 bytes)
  [[nodiscard]] double total_us() const noexcept {
    return soc_us + wait_soc_preq_us + prc_us + isochronous_us + async_us;
  }
};

// Multiplexed CNs (EPSG DS 301): one multiplexed cycle of `cycles` cycles for the network, each
// multiplexed CN polled in one of them, its slot (NMT_MultiplCycleAssign 0x1F9B/node, 1..cycles).
// A node without a slot (0) gets the one with the fewest nodes so far, the lowest of equals, in
// node-id order, after the given slots counted: the load spread over the multiplexed cycle.
struct MultiplexNode {
  uint8_t node_id = 0;
  uint8_t slot = 0;  // 0: to assign
};
inline void assign_multiplex_slots(std::span<MultiplexNode> nodes, uint8_t cycles) noexcept {
  if (cycles == 0) return;
  std::array<std::size_t, 256> load{};
  for (const MultiplexNode& n : nodes)
    if (n.slot != 0) ++load[n.slot];
  std::sort(nodes.begin(), nodes.end(),
            [](const MultiplexNode& a, const MultiplexNode& b) { return a.node_id < b.node_id; });
  for (MultiplexNode& n : nodes) {
    if (n.slot != 0) continue;
    uint8_t best = 1;
    for (unsigned k = 2; k <= cycles; ++k)
      if (load[k] < load[best]) best = static_cast<uint8_t>(k);
    n.slot = best;
    ++load[best];
  }
}

// PollResponse Chaining (EPSG DS 302-C): a chained CN takes its outputs from the PResMN, through
// an RPDO whose NodeID_U8 names the MN. The MN places the output images of the chained nodes one
// after the other in node-id order, each as its PReq image would be: `base` per node, and the
// end of the last one (the least PResMN payload, which the PRC slot's budget counts).
struct PresMnNode {
  uint8_t node_id = 0;
  uint16_t preq_size = 0;  // the node's output image (its layout's PReq bytes)
  uint16_t base = 0;       // filled: where it starts in the PResMN payload
};
// Fills each `base` (sorting the nodes by id); returns the end of the last image.
inline std::size_t place_pres_mn_outputs(std::span<PresMnNode> nodes) noexcept {
  std::sort(nodes.begin(), nodes.end(),
            [](const PresMnNode& a, const PresMnNode& b) { return a.node_id < b.node_id; });
  std::size_t end = 0;
  for (PresMnNode& n : nodes) {
    n.base = static_cast<uint16_t>(std::min<std::size_t>(end, 0xFFFF));
    end += n.preq_size;
  }
  return end;
}

[[nodiscard]] inline CycleBudget cycle_budget(std::span<const BudgetNode> nodes,
                                              uint32_t wait_soc_preq_us,
                                              uint32_t async_slot_timeout_us,
                                              uint16_t pres_mn_payload = 36,
                                              uint8_t multiplex_cycles = 0) noexcept {
  CycleBudget b;
  uint32_t prc_timeout_us = 0;
  for (const BudgetNode& n : nodes) {
    if (!n.prc) continue;
    b.prc_us += wire_time_us(24u + n.pres_payload) + 0.96;  // PRes + inter-frame gap
    prc_timeout_us = std::max(prc_timeout_us, n.pres_timeout_us);
    ++b.prc_nodes;
  }
  if (b.prc_nodes > 0) b.prc_us += wire_time_us(24u + pres_mn_payload) + prc_timeout_us;
  b.soc_us = wire_time_us(36);
  b.wait_soc_preq_us = wait_soc_preq_us;
  b.async_us = wire_time_us(23) + async_slot_timeout_us + wire_time_us(1514);
  // The continuous CNs in every cycle, the multiplexed ones in the cycle of their slot.
  const unsigned cycles = multiplex_cycles > 1 ? multiplex_cycles : 1;
  for (unsigned cycle = 1; cycle <= cycles; ++cycle) {
    double iso = 0;
    std::size_t polled = 0;
    for (const BudgetNode& n : nodes) {
      if (n.prc) continue;
      if (n.multiplex_slot != 0 && n.multiplex_slot != cycle) continue;
      iso += wire_time_us(24u + n.preq_payload) + n.pres_timeout_us +
             wire_time_us(24u + n.pres_payload);
      ++polled;
    }
    if (iso > b.isochronous_us) {
      b.isochronous_us = iso;
      b.polled_in_worst_cycle = polled;
    }
  }
  return b;
}

}  // namespace ds1928::powerlink
