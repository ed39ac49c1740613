// PollResponse Chaining between the Managing Node (PowerlinkBus) and simulated CNs
// (sim::PowerlinkCn) in one process, on simulated time: a mixed cycle (PRC nodes first, then
// PReq/PRes), the SyncRequest set-up, the fall-back of a CN without the PRC feature, the
// loss of a PRC CN's PRes (reset, then set up again), and the chained nodes' outputs in the
// PResMN (error acknowledgement and an EnDat command over Flatstream behind a PRC node).
#include <catch2/catch.hpp>

#include "endat/command.hpp"
#include "pl_sim_rig.hpp"
#include "powerlink/sync_frames.hpp"

using namespace pl_sim_rig;

TEST_CASE("A mixed cycle: PRC nodes answer the PResMN, the others their PReq", "[powerlink][prc]") {
  Setup s({{1, true, true}, {2, true, true}, {3, false, true}});
  REQUIRE(s.run_until_operational(4000));
  // Set up by SyncRequests: both in PRC mode, node 2 after node 1 by at least node 1's PRes on
  // the wire and an inter-frame gap.
  CHECK(s.cns[0]->prc_mode());
  CHECK(s.cns[1]->prc_mode());
  CHECK_FALSE(s.cns[2]->prc_mode());
  const pl::CnStatus n1 = s.node(1);
  const pl::CnStatus n2 = s.node(2);
  CHECK(n1.prc);
  CHECK(n2.prc);
  CHECK(n1.prc_pres_time_ns == 0);
  CHECK(n2.prc_predecessor == 1);
  CHECK(n2.prc_pres_time_ns >= pl::prc_frame_time_ns(n1.pres_size) + pl::kInterFrameGapNs);
  CHECK(s.cns[1]->pres_time_first_ns() == n2.prc_pres_time_ns);
  CHECK(n1.sync_responses >= 2);
  CHECK_FALSE(s.node(3).prc);
  // From now on: one PResMN per cycle, no PReq to the PRC nodes, every PRes in its slot.
  const auto preq1 = s.wire.preq_to[1];
  const auto preq2 = s.wire.preq_to[2];
  const auto preq3 = s.wire.preq_to[3];
  const auto pres_mn = s.wire.pres_mn;
  const uint32_t rx1 = n1.pres_received, rx2 = n2.pres_received, rx3 = s.node(3).pres_received;
  const int kCycles = 500;
  int fresh = 0;
  for (int i = 0; i < kCycles; ++i) {
    auto r = s.step();
    REQUIRE(r.bus_up);
    REQUIRE(r.frames_lost == 0);
    fresh += s.io[0].inputs_fresh && s.io[1].inputs_fresh && s.io[2].inputs_fresh;
  }
  CHECK(fresh == kCycles);
  CHECK(s.wire.preq_to[1] == preq1);
  CHECK(s.wire.preq_to[2] == preq2);
  CHECK(s.wire.preq_to[3] == preq3 + kCycles);
  CHECK(s.wire.pres_mn == pres_mn + kCycles);
  CHECK(s.node(1).pres_received == rx1 + kCycles);
  CHECK(s.node(2).pres_received == rx2 + kCycles);
  CHECK(s.node(3).pres_received == rx3 + kCycles);
  CHECK(s.node(1).loss_of_pres.events == 0);
  CHECK(s.node(2).late_pres.events == 0);
}

TEST_CASE("A CN without the PRC feature is polled with PReq/PRes and the fall-back reported",
          "[powerlink][prc]") {
  Setup s({{1, true, false}, {2, true, true}});
  REQUIRE(s.run_until_operational(4000));
  const pl::CnStatus n1 = s.node(1);
  CHECK(n1.prc_configured);
  CHECK(n1.prc_fallback);
  CHECK_FALSE(n1.prc);
  CHECK(n1.last_error == make_error_code(pl::MnError::kPrcNotSupported));
  CHECK_FALSE(s.cns[0]->prc_mode());
  // Node 2 is the first (and only) node of the chain: right after the PResMN.
  CHECK(s.node(2).prc);
  CHECK(s.node(2).prc_pres_time_ns == 0);
  const auto preq1 = s.wire.preq_to[1];
  for (int i = 0; i < 200; ++i) REQUIRE(s.step().bus_up);
  CHECK(s.wire.preq_to[1] == preq1 + 200);
  CHECK(s.wire.preq_to[2] == 0);
}

TEST_CASE("A PRC CN whose PRes stop is reset at its threshold and chained again",
          "[powerlink][prc]") {
  Setup s({{1, true, true}, {2, true, true}});
  REQUIRE(s.run_until_operational(4000));
  const uint32_t resets = s.node(2).resets;
  const uint32_t boots = s.node(2).boots;
  sim::PowerlinkCnFaults drop;
  drop.drop_pres = 1.0;
  s.cns[1]->set_faults(drop);
  // Threshold 15: two losses in a row reset it; node 1 keeps its slot meanwhile.
  bool reset_seen = false;
  for (int i = 0; i < 10 && !reset_seen; ++i) {
    (void)s.step();
    reset_seen = s.node(2).resets > resets;
  }
  REQUIRE(reset_seen);
  CHECK(s.node(2).last_reset_reason == make_error_code(pl::MnError::kLossOfPresThreshold));
  CHECK_FALSE(s.node(2).prc);
  CHECK(s.node(1).prc);
  CHECK(s.node(1).loss_of_pres.events == 0);
  s.cns[1]->set_faults({});
  bool back = false;
  for (int i = 0; i < 4000 && !back; ++i) back = s.step().bus_up && s.node(2).boots > boots;
  REQUIRE(back);
  CHECK(s.node(2).prc);
  CHECK(s.cns[1]->prc_mode());
  CHECK(s.wire.preq_to[2] == 0);
}

TEST_CASE("A CN that does not answer its SyncRequests is reset (PRC set-up failed)",
          "[powerlink][prc]") {
  // The CN advertises PRC but a fault drops its answers: here, by unplugging it from the wire
  // right after its identification.
  Setup s({{1, true, true}});
  (void)s.step();
  // The chain is set up in the second pass of "configure", after NMTResetConfiguration made the
  // CN take the objects written in the first.
  auto chaining = [&] {
    return s.node(1).boot == pl::CnBootState::kConfigure && s.node(1).configuration_resets > 0;
  };
  for (int i = 0; i < 4000 && !chaining(); ++i) (void)s.step();
  REQUIRE(chaining());
  s.wire.nodes.clear();
  bool reset = false;
  for (int i = 0; i < 2000 && !reset; ++i) {
    (void)s.step();
    reset = s.node(1).resets > 0;
  }
  REQUIRE(reset);
  CHECK(s.node(1).last_reset_reason == make_error_code(pl::MnError::kPrcSyncFailed));
}

TEST_CASE("A chained node takes its outputs from the PResMN at its RPDO's offsets",
          "[powerlink][prc]") {
  // Nodes 1 and 2 chained, node 3 polled: each chained node's outputs (OutputSequence | 7 Tx
  // bytes | AckErrorInfo, 9 bytes) in the PResMN by node id, node 1 at 0 and node 2 at 9; each
  // learns where from the RPDO the MN wrote to it (0x1401/1 = 240, 0x1601).
  Setup s({{1, true, true}, {2, true, true}, {3, false, true}});
  REQUIRE(s.run_until_operational(4000));
  REQUIRE(s.node(1).prc);
  REQUIRE(s.node(2).prc);
  CHECK(s.node(1).prc_outputs_offset == 0);
  CHECK(s.node(1).prc_outputs_size == 9);
  CHECK(s.node(2).prc_outputs_offset == 9);
  CHECK(s.node(3).prc_outputs_size == 0);
  for (uint8_t n : {1, 2}) {
    const auto* map = s.cns[n - 1]->pres_mn_layout();
    REQUIRE(map != nullptr);
    CHECK(s.cns[n - 1]->communication_objects().rpdo_source(pl::obj::kRxPdoCommPresMn) ==
          pl::kNodeMn);
    const pl::ModuleMapping* m = map->find(1);
    REQUIRE(m != nullptr);
    const uint16_t base = n == 1 ? 0 : 9;
    CHECK(m->fields.fixed[static_cast<std::size_t>(pl::ImageField::kOutputSequence)] == base);
    CHECK(m->fields.tx[0] == base + 1);
    CHECK(m->fields.fixed[static_cast<std::size_t>(pl::ImageField::kAckErrorInfo)] == base + 8);
  }
  // Distinct outputs per node: the PResMN carries them where the RPDOs say, RD = 1.
  s.io[0].outputs.tx_bytes[0] = 0x11;
  s.io[1].outputs.tx_bytes[0] = 0x22;
  s.io[2].outputs.tx_bytes[0] = 0x33;
  REQUIRE(s.step().bus_up);
  REQUIRE(s.wire.last_pres_mn.size() == 36);  // 18 bytes of outputs: the minimum frame stays
  CHECK(s.wire.last_pres_mn[1] == 0x11);
  CHECK(s.wire.last_pres_mn[10] == 0x22);
  CHECK(s.wire.last_pres_mn[19] == 0);  // node 3's outputs go in its PReq
  const uint64_t taken = s.cns[0]->stats().pres_mn_outputs;
  REQUIRE(s.step().bus_up);
  CHECK(s.cns[0]->stats().pres_mn_outputs == taken + 1);

  // Error acknowledgement behind each chained node: an injected ErrorInfo bit stays until the MN
  // writes it to AckErrorInfo, which reaches the module only through the PResMN.
  constexpr uint8_t kBit = 0x01;
  for (std::size_t a = 0; a < 2; ++a) s.cns[a]->module(0).inject_error(kBit);
  for (int i = 0; i < 20; ++i) REQUIRE(s.step().bus_up);
  for (std::size_t a = 0; a < 2; ++a) REQUIRE((s.io[a].inputs.error_info & kBit) != 0);
  for (std::size_t a = 0; a < 2; ++a) s.io[a].outputs.ack_error_info = kBit;
  bool cleared = false;
  for (int i = 0; i < 50 && !cleared; ++i) {
    REQUIRE(s.step().bus_up);
    cleared = (s.io[0].inputs.error_info & kBit) == 0 && (s.io[1].inputs.error_info & kBit) == 0;
  }
  CHECK(cleared);
}

TEST_CASE("An EnDat command over Flatstream to a module behind a PRC node", "[powerlink][prc]") {
  namespace endat = ds1928::endat;
  namespace fs = ds1928::flatstream;
  Setup s({{1, true, true}, {2, false, true}});
  REQUIRE(s.run_until_operational(4000));
  REQUIRE(s.node(1).prc);
  for (std::size_t a = 0; a < 2; ++a)
    s.tunnels.push_back(std::make_unique<fs::MasterChannel>(fs::MasterConfig{}));
  // Both axes: the chained one (its TxBytes in the PResMN) and the polled one answer alike.
  for (std::size_t a = 0; a < 2; ++a) {
    const auto request = endat::Request::read(0xA1, 13);
    auto message = endat::encode_request(request, endat::CommandSet::EnDat22);
    REQUIRE(message);
    REQUIRE_FALSE(s.tunnels[a]->submit(message->span(), 7));
    std::optional<fs::Message> reply;
    for (int i = 0; i < 2000 && !reply; ++i) {
      REQUIRE(s.step().bus_up);
      reply = s.tunnels[a]->take_received();
    }
    INFO("axis " << a);
    REQUIRE(reply);
    auto decoded = endat::decode_reply(request, reply->payload());
    REQUIRE(decoded);
    CHECK(decoded->echo.command == endat::Command::ReadParameter);
    CHECK(decoded->echo.parameter == 13);
  }
}
