// Managing Node (PowerlinkBus) and simulated CNs (sim::PowerlinkCn) in one process on simulated
// time: the wire every frame crosses, and a set-up of N nodes (PRC, multiplexed or polled), each
// with one X20DS1928 in slot 1. Used by the PRC and the multiplexing tests.
#pragma once

#include <catch2/catch.hpp>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "flatstream/channel.hpp"
#include "powerlink/frames.hpp"
#include "powerlink/link.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "sim/powerlink_cn.hpp"

namespace pl_sim_rig {

namespace pl = ds1928::powerlink;
namespace sim = ds1928::sim;

inline int64_t g_now_ns = 1'000'000'000;
inline int64_t fake_clock() noexcept {
  return g_now_ns;
}
constexpr int64_t kCycleNs = 1'000'000;
constexpr int64_t kWireNs = 1'000;

// Every frame the MN sends reaches every CN (the invited one last, as PowerlinkCnLoop does);
// the CNs' frames queue for the MN and reach the other CNs (a SyncResponse is timed by them).
// receive() runs the CNs' timers up to its deadline, so a PRes due after the PResMN leaves then.
class Wire final : public pl::Link {
 public:
  std::vector<sim::PowerlinkCn*> nodes;
  std::deque<std::vector<uint8_t>> to_mn;
  std::map<uint8_t, uint64_t> preq_to;  // PReqs per destination node
  uint64_t socs = 0;
  std::vector<bool> soc_mc;  // MC of each SoC
  struct PreqSeen {
    uint64_t soc;  // SoCs before it: the cycle it belongs to is soc - 1
    uint8_t node;
  };
  std::vector<PreqSeen> preqs;  // every PReq, in order
  uint64_t pres_mn = 0;
  std::vector<uint8_t> last_pres_mn;  // payload of the last PResMN

  std::error_code send(std::span<const uint8_t> frame) noexcept override {
    g_now_ns += kWireNs;
    const uint8_t type = frame[14] & 0x7F;
    if (type == 0x03) {
      ++preq_to[frame[15]];
      preqs.push_back({socs, frame[15]});
    }
    if (type == 0x01) {
      ++socs;
      if (auto f = pl::parse_frame(frame))
        if (const auto* soc = std::get_if<pl::Soc>(&f->message))
          soc_mc.push_back(soc->multiplexed_cycle_completed);
    }
    if (type == 0x04 && frame[16] == pl::kNodeMn) {
      ++pres_mn;
      if (auto f = pl::parse_frame(frame))
        if (const auto* p = std::get_if<pl::PRes>(&f->message))
          last_pres_mn.assign(p->payload.begin(), p->payload.end());
    }
    const uint8_t invited = type == 0x05 ? frame[21] : 0;
    sim::PowerlinkCn* last = nullptr;
    for (auto* n : nodes) {
      if (n->node_id() == invited) {
        last = n;
        continue;
      }
      n->receive(frame, g_now_ns);
    }
    if (last) last->receive(frame, g_now_ns);
    return {};
  }
  pl::Received receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept override {
    for (;;) {
      if (!to_mn.empty()) {
        auto f = std::move(to_mn.front());
        to_mn.pop_front();
        const std::size_t n = std::min(f.size(), buffer.size());
        std::copy_n(f.begin(), n, buffer.begin());
        g_now_ns += kWireNs;
        return {n, g_now_ns, {}};
      }
      int64_t next = INT64_MAX;
      for (auto* n : nodes) next = std::min(next, n->next_deadline_ns());
      if (next > deadline_ns) {
        if (deadline_ns > g_now_ns) g_now_ns = deadline_ns;
        return {};
      }
      g_now_ns = std::max(g_now_ns, next);
      for (auto* n : nodes) n->tick(g_now_ns);
    }
  }
  bool link_up() const noexcept override { return true; }
  pl::MacAddress mac() const noexcept override { return {0x02, 0, 0, 0, 0, 0xF0}; }
};

struct NodeSpec {
  uint8_t id;
  bool prc;                         // configured for PRC at the MN
  bool capable;                     // the CN advertises the PRC feature
  bool multiplexed = false;         // polled in one slot of the multiplexed cycle
  uint8_t multiplex_slot = 0;       // ... this one (0: the MN assigns it)
  uint8_t cn_multiplex_cycles = 0;  // written to the CN as 0x1F98/7 whatever the MN polls
  std::vector<ds1928::CnObjectWrite> writes{};    // further objects written at boot (a PDO mapping)
  std::vector<ds1928::InfoChannelConfig> info{};  // the axis' additional-information channels
};

struct Setup {
  Wire wire;
  std::vector<std::unique_ptr<sim::PowerlinkCn>> cns;
  std::unique_ptr<pl::PowerlinkBus> mn;
  std::vector<ds1928::AxisIo> io;
  uint64_t cycle = 0;

  explicit Setup(const std::vector<NodeSpec>& specs, uint8_t multiplex_cycles = 0) {
    pl::MnConfig config;
    config.cycle_us = 1000;
    config.bus.multiplex_cycles = multiplex_cycles;
    // Listening for another MN first (MNWaitNotAct) has tests of its own; these start at once.
    config.bus.nmt.wait_not_active_ms = 0;
    config.mac = wire.mac();
    config.bus.thresholds.loss_of_pres = 15;
    for (const NodeSpec& s : specs) {
      ds1928::PowerlinkNodeConfig node;
      node.node_id = s.id;
      node.pres_timeout_us = 100;
      node.prc = s.prc;
      node.multiplexed = s.multiplexed;
      if (s.multiplex_slot != 0) node.multiplex_slot = s.multiplex_slot;
      if (s.cn_multiplex_cycles != 0)
        node.object_writes.push_back(
            {pl::obj::kCycleTiming, pl::obj::kCycleTimingMultiplCycleCnt, {s.cn_multiplex_cycles}});
      node.object_writes.insert(node.object_writes.end(), s.writes.begin(), s.writes.end());
      config.bus.nodes.push_back(node);
      ds1928::AxisConfig axis;
      axis.node = s.id;
      axis.slot = 1;
      axis.info = s.info;
      for (std::size_t n = 0; n < s.info.size(); ++n)
        axis.module.info_cmd[n] = ds1928::encode_info_command(s.info[n].request);
      config.axes.push_back(axis);
      sim::PowerlinkCnConfig c;
      c.node_id = s.id;
      c.mac = {0x02, 0, 0, 0, 0x19, s.id};
      c.prc_capable = s.capable;
      c.power_off_ns = 50'000'000;
      const uint8_t me = s.id;
      cns.push_back(std::make_unique<sim::PowerlinkCn>(c, [this, me](std::span<const uint8_t> f) {
        wire.to_mn.emplace_back(f.begin(), f.end());
        for (auto* other : wire.nodes)
          if (other->node_id() != me) other->receive(f, g_now_ns);
      }));
      wire.nodes.push_back(cns.back().get());
    }
    mn = std::make_unique<pl::PowerlinkBus>(config, wire);
    mn->set_clock(&fake_clock);
    REQUIRE_FALSE(mn->start());
    io.resize(config.axes.size());
  }
  // Flatstream master channels of the axes, stepped as the daemon's cycle work does (null: the
  // axis' outputs are the test's).
  std::vector<std::unique_ptr<ds1928::flatstream::MasterChannel>> tunnels;
  ds1928::ExchangeResult step() {
    const int64_t start = (g_now_ns / kCycleNs + 1) * kCycleNs;
    g_now_ns = start;
    for (auto& c : cns) c->tick(g_now_ns);
    for (std::size_t i = 0; i < tunnels.size() && i < io.size(); ++i)
      if (tunnels[i])
        ds1928::flatstream::apply(tunnels[i]->step(ds1928::flatstream::input_frame(io[i].inputs),
                                                   static_cast<uint64_t>(start / 1000)),
                                  io[i].outputs);
    auto r = mn->exchange(io, start, cycle++);
    for (auto& c : cns) c->tick(g_now_ns);
    return r;
  }
  bool run_until_operational(int limit) {
    for (int i = 0; i < limit; ++i)
      if (step().bus_up) return true;
    return false;
  }
  const pl::CnStatus& node(uint8_t id) {
    static pl::CnStatus none;
    const auto st = mn->status();
    for (std::size_t i = 0; i < st.node_count; ++i)
      if (st.nodes[i].node == id) {
        none = st.nodes[i];
        return none;
      }
    FAIL("node not in status");
    return none;
  }
};

}  // namespace pl_sim_rig
