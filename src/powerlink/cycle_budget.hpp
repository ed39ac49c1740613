// Does a POWERLINK cycle fit its period? Two figures on the wire at 100 Mbit/s (seed 001):
// - nominal: every node answers as expected: SoC, WaitSoCPReq, per polled CN its PReq, its PRes
//   latency (pres_latency_us) and its PRes, then SoA, the invited answer's latency and one ASnd
//   of AsyncMTU (NMT_CycleTiming_REC.AsyncMTU_U16, 0x1F98/8: every asynchronous frame of the
//   network is at most that long);
// - worst case: every node times out: each PRes arrives just at its PRes timeout and the ASnd
//   just at the AsyncSlotTimeout (0x1F8A/2).
// Multiplexed CNs (EPSG DS 301) count in the cycle of their slot of the multiplexed cycle; the
// fullest cycle is what must fit. PRC nodes (PollResponse Chaining) take the PRC slot instead:
// the PResMN, each PRC node's PRes with an inter-frame gap before it (the propagation delay the
// MN assigns, at least that), and past the last PRes time the longest latency (nominal) or PRes
// timeout (worst) among them. The configuration refuses a nominal cycle that does not fit and
// warns about a worst case that does not (docs/powerlink.md, cycle budget).
// Header-only and pure: the configuration check, the daemon's status and the benchmarks use it.
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
  uint8_t multiplex_slot = 0;    // 0 = every cycle, k = cycle k of each multiplexed cycle
  bool prc = false;              // PollResponse Chaining: in the PRC slot, not polled with PReq
  uint32_t pres_latency_us = 2;  // PReq received → PRes sent, expected (nominal figure)
};

enum class BudgetCase : uint8_t {
  kNominal,  // each node answers within its expected latency
  kWorst,    // each node answers just at its timeout
};
[[nodiscard]] constexpr const char* to_string(BudgetCase c) noexcept {
  return c == BudgetCase::kNominal ? "nominal" : "worst";
}

// The network-wide figures of the budget.
struct BudgetNetwork {
  uint32_t wait_soc_preq_us = 0;         // WaitSoCPReq (0x1F8A/1)
  uint32_t async_slot_timeout_us = 100;  // AsyncSlotTimeout (0x1F8A/2)
  uint16_t async_mtu = 300;              // AsyncMTU (0x1F98/8), bytes after the Ethernet header
  uint16_t pres_mn_payload = 36;         // PResMN payload when PRC nodes are present
  uint8_t multiplex_cycles = 0;          // MultiplCycleCnt (0x1F98/7)
};

struct CycleBudget {
  BudgetCase which = BudgetCase::kWorst;
  double soc_us = 0;
  double wait_soc_preq_us = 0;
  double prc_us = 0;  // PResMN + the PRC nodes' PRes + their longest latency/timeout (0: no PRC)
  std::size_t prc_nodes = 0;
  double isochronous_us = 0;  // PReq + latency/timeout + PRes of the CNs of the fullest cycle
  std::size_t polled_in_worst_cycle = 0;
  double soa_us = 0;
  double async_wait_us = 0;  // SoA to the ASnd: the invited node's latency, or AsyncSlotTimeout
  double asnd_us = 0;        // one ASnd of AsyncMTU
  [[nodiscard]] double async_us() const noexcept { return soa_us + async_wait_us + asnd_us; }
  [[nodiscard]] double total_us() const noexcept {
    return soc_us + wait_soc_preq_us + prc_us + isochronous_us + async_us();
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

// The largest frame an AsyncMTU allows on the wire: Ethernet header (14) + AsyncMTU bytes.
[[nodiscard]] constexpr std::size_t async_frame_length(uint16_t async_mtu) noexcept {
  return 14u + async_mtu;
}

[[nodiscard]] inline CycleBudget cycle_budget(std::span<const BudgetNode> nodes,
                                              const BudgetNetwork& net, BudgetCase which) noexcept {
  CycleBudget b;
  b.which = which;
  // What a node's answer costs past its request: its latency, but never more than the MN
  // waits for it (a latency beyond the timeout is a timeout).
  const auto wait = [which](uint32_t latency_us, uint32_t timeout_us) -> uint32_t {
    return which == BudgetCase::kWorst ? timeout_us : std::min(latency_us, timeout_us);
  };
  uint32_t prc_wait_us = 0;
  uint32_t slowest_us = 0;  // the slowest expected answer of any node (the invited ASnd)
  for (const BudgetNode& n : nodes) {
    slowest_us = std::max(slowest_us, n.pres_latency_us);
    if (!n.prc) continue;
    b.prc_us += wire_time_us(24u + n.pres_payload) + 0.96;  // PRes + inter-frame gap
    prc_wait_us = std::max(prc_wait_us, wait(n.pres_latency_us, n.pres_timeout_us));
    ++b.prc_nodes;
  }
  if (b.prc_nodes > 0) b.prc_us += wire_time_us(24u + net.pres_mn_payload) + prc_wait_us;
  b.soc_us = wire_time_us(36);
  b.wait_soc_preq_us = net.wait_soc_preq_us;
  b.soa_us = wire_time_us(23);
  b.async_wait_us = wait(slowest_us, net.async_slot_timeout_us);
  b.asnd_us = wire_time_us(async_frame_length(net.async_mtu));
  // The continuous CNs in every cycle, the multiplexed ones in the cycle of their slot.
  const unsigned cycles = net.multiplex_cycles > 1 ? net.multiplex_cycles : 1;
  for (unsigned cycle = 1; cycle <= cycles; ++cycle) {
    double iso = 0;
    std::size_t polled = 0;
    for (const BudgetNode& n : nodes) {
      if (n.prc) continue;
      if (n.multiplex_slot != 0 && n.multiplex_slot != cycle) continue;
      iso += wire_time_us(24u + n.preq_payload) + wait(n.pres_latency_us, n.pres_timeout_us) +
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
