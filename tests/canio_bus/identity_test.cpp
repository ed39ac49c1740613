// The expected topology on CAN-I/O, in virtual time (stepped rig: fake clock, the timed virtual
// bus, strict simulated CANopen nodes): the driver reads each node's identity objects (0x1000,
// 0x1018/1..4, the ones canio.nodes[] expects) before it configures the node's modules. A node
// that reports another product keeps exactly its axes down with the reason, the other node's
// axis delivers exact positions; with on_mismatch warn it is reported and delivers; a node
// replaced while the bus runs (boot-up with another identity) goes down at its boot-up; a node
// without the identity object is refused when an identity is expected and not read otherwise.
#include <catch2/catch.hpp>
#include <map>

#include "canio/canio_options.hpp"
#include "rig.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using namespace ds1928::test;

namespace {

constexpr uint32_t kVendor = 0x0000001A;
constexpr uint32_t kProduct = 0x00001928;
constexpr uint32_t kWrongProduct = 0x0000BEEF;

uint64_t position_of(const ModuleInputs& in) {
  return (uint64_t{in.position_hw} << 32) | in.position_lw;
}

// Two nodes (one axis each), both expected as vendor kVendor, product kProduct; node 2's serial
// too.
DaemonConfig two_nodes() {
  DaemonConfig c = canio_config(2);
  for (uint8_t n : {uint8_t{1}, uint8_t{2}}) {
    CanioNodeOptions o;
    o.node = n;
    o.identity.vendor_id = kVendor;
    o.identity.product_code = kProduct;
    if (n == 2) o.identity.serial_no = 0x00000202;
    c.canio.nodes.push_back(o);
  }
  return c;
}

// Runs stepped cycles; per axis: fresh samples, and fresh samples that are not what that axis'
// node sent for that very SYNC (a position under the wrong axis' name would count here).
struct Run {
  explicit Run(Rig& r) : rig(r) {
    for (std::size_t k = 0; k < rig.nodes.size(); ++k)
      rig.nodes[k]->on_inputs = [this, k](std::size_t, int64_t t, const ModuleInputs& in) {
        sent[k][static_cast<uint64_t>((t - Rig::kT0) / period_ns())] = in;
      };
  }
  [[nodiscard]] int64_t period_ns() const { return int64_t{rig.config.cycle.period_us} * 1000; }
  void step() {
    (void)rig.cycle(c);
    for (std::size_t i = 0; i < rig.io.size(); ++i) {
      if (!rig.io[i].inputs_fresh) continue;
      ++fresh[i];
      const auto it = sent[i].find(c);
      if (it == sent[i].end() || position_of(it->second) != position_of(rig.io[i].inputs)) ++wrong;
    }
    for (auto& s : sent) s.second.erase(c);
    ++c;
  }
  template <class Done>
  bool until(Done done, uint64_t max_cycles = 20000) {
    for (uint64_t i = 0; i < max_cycles; ++i) {
      step();
      if (done()) return true;
    }
    return false;
  }
  void cycles(uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) step();
  }
  Rig& rig;
  uint64_t c = 0;
  std::map<std::size_t, uint64_t> fresh;
  uint64_t wrong = 0;
  std::map<std::size_t, std::map<uint64_t, ModuleInputs>> sent;
};

std::vector<canio::CanioNodeEvent> events(canio::CanioBus& bus) {
  std::vector<canio::CanioNodeEvent> out;
  canio::CanioNodeEvent e;
  while (bus.poll_event(e)) out.push_back(e);
  return out;
}

std::size_t count_events(const std::vector<canio::CanioNodeEvent>& v, canio::CanioNodeEventKind k,
                         uint8_t node) {
  std::size_t n = 0;
  for (const auto& e : v) n += e.kind == k && e.node == node;
  return n;
}

sim::CanioNodeIdentity identity(uint8_t node, uint32_t product = kProduct) {
  sim::CanioNodeIdentity id;
  id.vendor_id = kVendor;
  id.product_code = product;
  id.serial_no = 0x00000200 + node;
  return id;
}

uint32_t endat_mode_of(sim::CanioNode& n) {
  uint32_t v = 0;
  (void)n.module(0).read_register(reg::kEnDatMode, 1, v);
  return v;
}

}  // namespace

TEST_CASE(
    "CAN-I/O topology: a node with the wrong product keeps exactly its axis down with the "
    "reason, and recovers once corrected",
    "[canio][topology]") {
  Rig rig(two_nodes(), true, false, [](sim::CanioNodeConfig& nc) {
    nc.identity = identity(nc.node, nc.node == 2 ? kWrongProduct : kProduct);
  });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh[0] >= 500; }));
  const auto& ac1 = rig.canio->axis_counters(1);
  CHECK(run.fresh[1] == 0);
  CHECK_FALSE(rig.io[1].axis_up);
  CHECK(ac1.state.load() == canio::CanioAxisState::IdentityMismatch);
  CHECK(ac1.configurations.load() == 0);
  CHECK(run.wrong == 0);
  const std::string reason = rig.canio->axis_reason(1);
  CHECK_THAT(reason, Catch::StartsWith("identity: product_code 0x0000BEEF, expected 0x00001928 "
                                       "(0x1018/2)"));
  CHECK_THAT(reason, Catch::Contains("not started"));
  CHECK(rig.canio->axis_reason(0).empty());
  const canio::NodeIdentity id = rig.canio->node_identity(1);
  CHECK(id.state == canio::NodeIdentityState::Mismatch);
  CHECK(id.found[2] == kWrongProduct);
  CHECK(id.found[4] == 0x00000202);  // read, and as expected
  CHECK(id.mismatches >= 1);
  CHECK(rig.canio->node_identity(0).state == canio::NodeIdentityState::Confirmed);
  // Not configured, not started: the wrong node never left pre-operational, EnDat disabled.
  CHECK(rig.nodes[1]->nmt_state() == canio::NmtState::PreOperational);
  CHECK(endat_mode_of(*rig.nodes[1]) == 0);
  CHECK(rig.canio->node_counters(1).nmt_starts.load() == 0);
  const auto ev = events(*rig.canio);
  CHECK(count_events(ev, canio::CanioNodeEventKind::IdentityMismatch, 2) == 1);  // not per retry
  CHECK(count_events(ev, canio::CanioNodeEventKind::IdentityMismatch, 1) == 0);
  // Checked again with back-off (0.5, 1, 2, ... s): the same mismatch, no new event.
  const uint64_t checks = id.checks;
  run.cycles(2000);  // 4 s
  CHECK(rig.canio->node_identity(1).checks > checks);
  CHECK(run.fresh[1] == 0);

  // The right node on the cable (the fault put right): found at the next check, configured.
  rig.nodes[1]->set_identity(identity(2));
  REQUIRE(run.until([&] { return run.fresh[1] >= 100; }));
  CHECK(run.wrong == 0);
  CHECK(rig.canio->node_identity(1).state == canio::NodeIdentityState::Confirmed);
  CHECK(count_events(events(*rig.canio), canio::CanioNodeEventKind::IdentityConfirmed, 2) == 1);
  CHECK(rig.canio->axis_reason(1).empty());
}

TEST_CASE("CAN-I/O topology: with on_mismatch warn the node is reported and delivers",
          "[canio][topology]") {
  DaemonConfig config = two_nodes();
  config.topology.refuse = false;
  Rig rig(config, true, false, [](sim::CanioNodeConfig& nc) {
    nc.identity = identity(nc.node, nc.node == 2 ? kWrongProduct : kProduct);
  });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh[0] >= 200 && run.fresh[1] >= 200; }));
  CHECK(run.wrong == 0);
  CHECK(rig.canio->node_identity(1).state == canio::NodeIdentityState::Mismatch);
  CHECK(count_events(events(*rig.canio), canio::CanioNodeEventKind::IdentityMismatch, 2) == 1);
  CHECK(rig.canio->axis_counters(1).state.load() == canio::CanioAxisState::Operational);
}

TEST_CASE(
    "CAN-I/O topology: a node replaced while the bus runs (boot-up with another identity) goes "
    "down at its boot-up and stays down",
    "[canio][topology][bootup]") {
  Rig rig(two_nodes(), true, false,
          [](sim::CanioNodeConfig& nc) { nc.identity = identity(nc.node); });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh[0] >= 200 && run.fresh[1] >= 200; }));
  CHECK(rig.canio->node_identity(1).state == canio::NodeIdentityState::Confirmed);
  (void)events(*rig.canio);

  // Another bus controller on node 2's cable: another product, power-up settings, boot-up.
  const uint64_t boot_ups = rig.canio->node_counters(1).boot_ups.load();
  rig.nodes[1]->set_identity(identity(2, kWrongProduct));
  rig.nodes[1]->request_reset();
  const uint64_t fresh0 = run.fresh[0], fresh1 = run.fresh[1];
  run.cycles(3000);                      // 6 s: several checks with back-off
  CHECK(run.fresh[1] == fresh1);         // nothing from the replaced node after its boot-up
  CHECK(run.fresh[0] >= fresh0 + 2900);  // node 1 unaffected
  CHECK(run.wrong == 0);
  CHECK(rig.canio->node_counters(1).boot_ups.load() == boot_ups + 1);
  CHECK(rig.canio->axis_counters(1).state.load() == canio::CanioAxisState::IdentityMismatch);
  CHECK_THAT(rig.canio->axis_reason(1), Catch::StartsWith("identity: product_code 0x0000BEEF"));
  CHECK(rig.nodes[1]->nmt_state() == canio::NmtState::PreOperational);
  CHECK(endat_mode_of(*rig.nodes[1]) == 0);  // not configured either
  const auto ev = events(*rig.canio);
  CHECK(count_events(ev, canio::CanioNodeEventKind::BootUp, 2) == 1);
  CHECK(count_events(ev, canio::CanioNodeEventKind::IdentityMismatch, 2) == 1);
}

TEST_CASE(
    "CAN-I/O topology: without an identity object a node is refused when one is expected, not "
    "read when none is",
    "[canio][topology]") {
  DaemonConfig config = two_nodes();
  config.canio.nodes.erase(config.canio.nodes.begin());  // node 1: nothing expected
  Rig rig(config, true, false, [](sim::CanioNodeConfig& nc) { nc.identity.present = false; });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh[0] >= 300; }));
  CHECK(run.fresh[1] == 0);
  CHECK(rig.canio->node_identity(0).state == canio::NodeIdentityState::Unchecked);
  CHECK(rig.canio->node_identity(0).checks == 0);
  const canio::NodeIdentity id = rig.canio->node_identity(1);
  CHECK(id.state == canio::NodeIdentityState::Unreadable);
  CHECK(id.unreadable_mask == 0b10110);  // vendor, product, serial: each refused
  CHECK_THAT(rig.canio->axis_reason(1),
             Catch::StartsWith("identity: vendor_id unreadable, expected 0x0000001A (0x1018/1: "));
  CHECK_THAT(rig.canio->axis_reason(1), Catch::Contains("0x06020000"));
  CHECK(rig.canio->axis_counters(1).state.load() == canio::CanioAxisState::IdentityMismatch);
}

TEST_CASE(
    "CAN-I/O topology: another node on the cable after a silence (no boot-up heard) is read "
    "again before it delivers",
    "[canio][topology]") {
  // A self-starting node that keeps its settings: only the identity tells it from the first.
  DaemonConfig config = two_nodes();
  config.canio.nmt = CanNmt::None;
  Rig rig(config, true, false, [](sim::CanioNodeConfig& nc) {
    nc.identity = identity(nc.node);
    nc.self_start = true;
    nc.faults.config_write_only = false;  // the check after silence could pass on its registers
  });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh[0] >= 200 && run.fresh[1] >= 200; }));
  const uint64_t checks = rig.canio->node_identity(1).checks;
  rig.nodes[1]->set_silent(true);
  run.cycles(50);  // 100 ms: silent (input_timeout_ms 20)
  rig.nodes[1]->set_identity(identity(2, kWrongProduct));
  rig.nodes[1]->set_silent(false);
  const uint64_t fresh1 = run.fresh[1];
  run.cycles(2000);
  CHECK(run.fresh[1] == fresh1);
  CHECK(run.wrong == 0);
  CHECK(rig.canio->node_identity(1).checks > checks);
  CHECK(rig.canio->node_identity(1).state == canio::NodeIdentityState::Mismatch);
  CHECK(rig.canio->axis_counters(1).state.load() == canio::CanioAxisState::IdentityMismatch);
}
