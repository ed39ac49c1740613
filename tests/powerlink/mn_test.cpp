#include <catch2/catch.hpp>
#include <functional>
#include <memory>
#include <string>

#include "core/axis_sample.hpp"
#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "test_cn.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;
using test::MemoryLink;
using test::TestCn;

namespace {

using test::fake_clock;
using test::g_clock_ns;
using test::g_clock_step_ns;
using test::kPeriodNs;
using test::le;
using test::Rig;

}  // namespace

TEST_CASE("MN boots an in-memory CN to OPERATIONAL and configures its modules by SDO",
          "[powerlink][mn]") {
  Rig rig({1}, 2);
  TestCn& cn = *rig.cns[0];
  cn.inputs.position_lw = 0xCAFE;
  cn.inputs.error_info = 0x10;
  rig.link.log = true;
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  CHECK(cn.state == NmtState::kOperational);
  CHECK(rig.bus->managing_node().mn_state() == NmtState::kOperational);
  const CnStatus& st = rig.st(1);
  CHECK(st.boot == CnBootState::kOperational);
  CHECK(st.boots == 1);
  CHECK(st.sdo_errors == 0);
  CHECK(st.mac == cn.mac);
  CHECK(st.pres_size == 2 * pres_module_size(7));
  // Every module got its settings before EnableReadyToOperate (docs/powerlink.md mapping).
  CHECK(le(cn.objects[{0x2001, 0x01}]) == ModuleSettings{}.endat_mode());
  CHECK(le(cn.objects[{0x2001, 0x02}]) == 4);     // prescaler of slot 1
  CHECK(le(cn.objects[{0x2002, 0x02}]) == 5);     // prescaler of slot 2
  CHECK(le(cn.objects[{0x2002, 0x05}]) == 1);     // SinCosEnable
  CHECK(le(cn.objects[{0x2002, 0x06}]) == 1);     // SinCosRefSource
  CHECK(cn.objects[{0x2001, 0x09}].size() == 4);  // SinCosQuitTime UDINT
  CHECK(le(cn.objects[{0x2001, 0x09}]) == 100000);
  CHECK(le(cn.objects[{0x2001, 0x0B}]) == 7);  // InputMTU
  // 28 settings and identity objects, and per module the Rescan (EnDatAck bit 1) written after
  // EnDatMode (datasheet §11.6.2.3).
  CHECK(cn.objects.size() == 30);

  // The first frame of a boot is a reduced cycle: an SoA with IdentRequest, no SoC.
  REQUIRE_FALSE(rig.link.sent_log.empty());
  auto first = parse_soa(rig.link.sent_log.front());
  REQUIRE(first);
  CHECK(first->service == RequestedService::kIdentRequest);
  CHECK(first->target == 1);

  // Process data both ways, PReq RD once the MN is operational.
  for (auto& io : rig.axes) io.outputs.output_sequence = 0x42;
  rig.axes[0].outputs.tx_bytes[0] = 0x99;
  auto r = rig.step();
  CHECK(r.bus_up);
  CHECK(r.frames_lost == 0);
  CHECK(r.net_time.valid);
  CHECK(cn.last_preq_ready);
  CHECK(cn.last_outputs.output_sequence == 0x42);
  CHECK(cn.last_outputs.tx_bytes[0] == 0x99);
  REQUIRE(rig.axes[1].inputs_fresh);
  CHECK(rig.axes[1].inputs.position_lw == 0xCAFE);
  CHECK(rig.axes[1].inputs.error_info == 0x10);
  // PosTime = low 32 bits of the SoC's RelativeTime (offset 0).
  CHECK(rig.axes[0].inputs.pos_time_us == static_cast<uint32_t>(r.net_time.net_time_us));
  CHECK(r.net_time.net_time_us == (rig.cycle - 1) * 1000);
}

TEST_CASE("RelativeTime and the NetTimeRef are the SoC's send instant, not the nominal start",
          "[powerlink][mn][nettime]") {
  Rig rig({1}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // From here every clock read costs 1 µs, so the SoC's send instant differs from the nominal
  // cycle start, from the wake-up instant and from any other instant of the exchange.
  g_clock_step_ns = 1000;
  int64_t soc_sent_at = -1;
  uint64_t soc_relative_us = 0;
  rig.link.on_send = [&](std::span<const uint8_t> frame) {
    if (auto soc = parse_soc(frame)) {
      soc_sent_at = g_clock_ns;  // the simulated time at which the SoC is handed to the link
      soc_relative_us = soc->relative_time_us;
    }
  };
  uint64_t previous_relative_us = 0;
  // Wake-up latencies: none, typical, a p99 one, a 3 ms stall (the driver skips the missed
  // cycles), typical again.
  for (int64_t wake_ns :
       {int64_t{0}, int64_t{37'000}, int64_t{240'000}, int64_t{3'000'000}, int64_t{45'000}}) {
    const int64_t nominal = static_cast<int64_t>(rig.cycle) * kPeriodNs;
    soc_sent_at = -1;
    const ExchangeResult r = rig.step(wake_ns);
    if (wake_ns >= kPeriodNs) rig.cycle += static_cast<uint64_t>(wake_ns / kPeriodNs);
    REQUIRE(soc_sent_at >= nominal + wake_ns);
    REQUIRE(r.net_time.valid);
    CHECK(r.net_time.monotonic_ns == soc_sent_at);
    // The first exchange's nominal start (0) is RelativeTime 0.
    CHECK(soc_relative_us == static_cast<uint64_t>(soc_sent_at / 1000));
    CHECK(r.net_time.net_time_us == soc_relative_us);
    CHECK(soc_relative_us > previous_relative_us);
    previous_relative_us = soc_relative_us;
    // The CN stamps its inputs with the SoC's RelativeTime; mapped back through the NetTimeRef
    // (as the daemon does) the stamp lands on the SoC's send instant, whatever the wake-up delay.
    REQUIRE(rig.axes[0].inputs_fresh);
    CHECK(net_time_to_monotonic_ns(rig.axes[0].inputs.pos_time_us, r.net_time) == soc_sent_at);
  }
  // A driver that does not skip the cycles missed in a stall calls exchange() with a nominal
  // start before the previous SoC: RelativeTime still never goes backwards, and the reference
  // stays the instant that RelativeTime denotes.
  rig.cycle -= 3;
  const ExchangeResult r = rig.step(10'000);
  CHECK(soc_relative_us == previous_relative_us);
  CHECK(r.net_time.net_time_us == soc_relative_us);
  CHECK(r.net_time.monotonic_ns == static_cast<int64_t>(soc_relative_us) * 1000);
}

TEST_CASE("Loss-of-PRes threshold removes, resets and re-boots the CN", "[powerlink][mn]") {
  Rig rig({1, 2}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  TestCn& cn = *rig.cns[0];
  const int nmt_before = cn.nmt_commands;
  cn.drop_pres = true;
  auto r = rig.step();
  CHECK(r.frames_lost == 1);
  CHECK(rig.st(1).boot == CnBootState::kOperational);  // one loss: 8 < 15
  rig.step();                                          // second: 16 ≥ 15
  CHECK(rig.st(1).boot == CnBootState::kReset);
  CHECK(rig.st(1).loss_of_pres.fired == 1);
  CHECK(rig.st(1).last_reset_reason == MnError::kLossOfPresThreshold);
  CHECK_FALSE(rig.st(1).in_isochronous);
  CHECK(rig.st(2).boot == CnBootState::kOperational);  // the other CN is untouched
  cn.drop_pres = false;
  REQUIRE(rig.run_until([&] { return rig.st(1).boot == CnBootState::kOperational; }));
  CHECK(cn.nmt_commands > nmt_before);  // NMTResetNode, EnableReadyToOperate, StartNode
  CHECK(rig.st(1).boots == 2);
  CHECK(rig.st(1).resets == 1);
  // The reason outlives the re-boot (status shows why the last reset happened).
  CHECK(rig.st(1).last_reset_reason == MnError::kLossOfPresThreshold);
  CHECK_FALSE(rig.st(1).last_error);
  CHECK(rig.bus->state() == BusState::Operational);
}

TEST_CASE("Occasional PRes loss stays below the threshold", "[powerlink][mn]") {
  Rig rig({1}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  for (int i = 0; i < 400; ++i) {
    rig.cns[0]->drop_pres = (i % 10) == 0;  // 10 % loss, never two in a row
    auto r = rig.step();
    if (rig.cns[0]->drop_pres) {
      CHECK_FALSE(rig.axes[0].inputs_fresh);
      CHECK(r.frames_lost == 1);
    } else {
      CHECK(rig.axes[0].inputs_fresh);
    }
  }
  CHECK(rig.st(1).boots == 1);
  CHECK(rig.st(1).loss_of_pres.events == 40);
  CHECK(rig.st(1).loss_of_pres.fired == 0);
}

TEST_CASE("A late PRes is never taken for the next cycle's fresh input", "[powerlink][mn][stale]") {
  Rig rig({1, 2}, 1);
  // Several missing answers in a row are the point here, not a reason to reset the CN.
  rig.config.bus.thresholds.loss_of_pres = 0;
  rig.bus = std::make_unique<PowerlinkBus>(rig.config, rig.link);
  rig.bus->set_clock(&fake_clock);
  REQUIRE_FALSE(rig.bus->start());
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  TestCn& cn1 = *rig.cns[0];
  TestCn& cn2 = *rig.cns[1];
  cn1.inputs.position_lw = 0xAAAA;  // "old" data, answered too late
  cn2.inputs.position_lw = 0xAAAA;

  SECTION("arriving between two cycles") {
    cn1.hold_pres = true;
    rig.step();
    CHECK_FALSE(rig.axes[0].inputs_fresh);
    REQUIRE(cn1.held_pres.size() == 1);
    // The PRes arrives after the MN's end of cycle, before the next SoC.
    rig.link.rx.push_back(cn1.held_pres.front());
    cn1.held_pres.clear();
    cn1.hold_pres = false;
    cn1.drop_pres = true;  // and the CN does not answer the next PReq
    rig.step();
    CHECK_FALSE(rig.axes[0].inputs_fresh);
    CHECK(rig.st(1).stale_pres_dropped == 1);
    // Answered again: the fresh data, never the late one.
    cn1.drop_pres = false;
    cn1.hold_pres = true;
    rig.step();
    rig.link.rx.push_back(cn1.held_pres.front());
    cn1.held_pres.clear();
    cn1.hold_pres = false;
    cn1.inputs.position_lw = 0xBBBB;
    const uint32_t preqs_before = rig.st(1).pres_received;
    rig.step();
    REQUIRE(rig.axes[0].inputs_fresh);
    CHECK(rig.axes[0].inputs.position_lw == 0xBBBB);
    CHECK(rig.axes[0].inputs.pos_time_us ==
          static_cast<uint32_t>(rig.bus->managing_node().relative_time_us()));
    CHECK(rig.st(1).pres_received == preqs_before + 1);
    CHECK(rig.st(1).stale_pres_dropped == 2);
    CHECK(rig.st(1).late_pres.events >= 2);
  }
  SECTION("arriving within the cycle, before the node's own PReq") {
    cn2.hold_pres = true;
    rig.step();
    CHECK_FALSE(rig.axes[1].inputs_fresh);
    REQUIRE(cn2.held_pres.size() == 1);
    cn2.hold_pres = false;
    // Node 2's late PRes arrives right after node 1's PRes, before the PReq to node 2.
    rig.link.on_send = [&](std::span<const uint8_t> frame) {
      auto preq = parse_frame(frame);
      if (preq && preq->header.type == MessageType::kPReq && preq->header.dst_node == 1 &&
          !cn2.held_pres.empty()) {
        rig.link.rx.push_back(cn2.held_pres.front());
        cn2.held_pres.clear();
      }
    };
    cn2.drop_pres = true;
    rig.step();
    CHECK(rig.axes[0].inputs_fresh);
    CHECK_FALSE(rig.axes[1].inputs_fresh);
    CHECK(rig.st(2).stale_pres_dropped == 1);
    // Same again, with the CN answering the new PReq: the new data is published.
    cn2.drop_pres = false;
    cn2.hold_pres = true;
    rig.step();
    cn2.hold_pres = false;
    cn2.inputs.position_lw = 0xCCCC;
    rig.step();
    REQUIRE(rig.axes[1].inputs_fresh);
    CHECK(rig.axes[1].inputs.position_lw == 0xCCCC);
    CHECK(rig.st(2).stale_pres_dropped == 2);
  }
  CHECK(rig.st(1).boot == CnBootState::kOperational);
  CHECK(rig.st(2).boot == CnBootState::kOperational);
  CHECK(rig.bus->managing_node().counters().unexpected_frames == 0);
}

TEST_CASE("Async timeouts count only unanswered Ident/StatusRequests", "[powerlink][mn][async]") {
  Rig rig({1}, 1);
  TestCn& cn = *rig.cns[0];
  int invites = 0, unspecified = 0;
  rig.link.on_send = [&](std::span<const uint8_t> frame) {
    if (auto soa = parse_soa(frame); soa && soa->target == 1) {
      ++invites;
      if (soa->service == RequestedService::kUnspecifiedInvite) ++unspecified;
    }
  };
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  const MnCounters& c = rig.bus->managing_node().counters();
  // A CN that answers every Ident/StatusRequest: no timeout, whatever it did with the other
  // invitations.
  CHECK(cn.status_requests > 0);
  CHECK(c.async_timeouts == 0);

  // Operational, the CN claims RS > 0 but has nothing to send: invited every few cycles, never
  // answers, and that is no timeout.
  cn.fake_request_count = 2;
  const uint32_t unused_before = c.async_invites_unused;
  unspecified = 0;
  for (int i = 0; i < 60; ++i) rig.step();
  CHECK(unspecified >= 20);
  CHECK(c.async_invites_unused - unused_before == static_cast<uint32_t>(unspecified));
  CHECK(c.async_timeouts == 0);
  cn.fake_request_count = 0;

  // A CN that ignores StatusRequests (its boot stalls in wait_pre_operational_2): each one is a
  // timeout, and nothing else is.
  Rig mute({1}, 1);
  mute.cns[0]->ignore_status_requests = true;
  for (int i = 0; i < 600; ++i) mute.step();
  CHECK(mute.st(1).boot == CnBootState::kWaitPreOp2);
  CHECK(mute.cns[0]->status_requests >= 20);
  CHECK(mute.bus->managing_node().counters().async_timeouts ==
        static_cast<uint32_t>(mute.cns[0]->status_requests));
  CHECK(invites > 0);
}

TEST_CASE("A CN stuck in a boot step is reset after the boot step timeout", "[powerlink][mn]") {
  Rig rig({1}, 1);
  rig.config.bus.nmt.boot_step_timeout_ms = 200;  // cycles are 1 ms
  rig.bus = std::make_unique<PowerlinkBus>(rig.config, rig.link);
  rig.bus->set_clock(&fake_clock);
  REQUIRE_FALSE(rig.bus->start());
  rig.cns[0]->ignore_status_requests = true;  // never confirms PRE_OPERATIONAL_2
  REQUIRE(rig.run_until([&] { return rig.st(1).boot == CnBootState::kWaitPreOp2; }));
  const uint64_t entered = rig.cycle;
  REQUIRE(rig.run_until([&] { return rig.st(1).resets == 1; }, 400));
  CHECK(rig.cycle - entered >= 200);
  CHECK(rig.cycle - entered <= 202);
  CHECK(rig.st(1).last_reset_reason == MnError::kBootStepTimeout);
  CHECK(rig.st(1).last_reset_reason.message() == "boot step timed out");
}

TEST_CASE("NMTRequests: a CN's own reset is served, anything else refused", "[powerlink][mn]") {
  Rig rig({1, 2}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  TestCn& cn = *rig.cns[0];

  SECTION("a CN asks for its own reset: booted and configured again") {
    cn.objects.clear();  // the MN must write the configuration again
    cn.nmt_request = NmtRequest{static_cast<uint8_t>(NmtCommandId::kResetNode), 1, {}};
    REQUIRE(rig.run_until([&] { return rig.st(1).resets == 1; }, 50));
    CHECK(cn.nmt_request_invites == 1);
    CHECK(rig.st(1).nmt_requests == 1);
    CHECK(rig.st(1).nmt_requests_refused == 0);
    CHECK(rig.st(1).last_reset_reason == MnError::kResetRequested);
    REQUIRE(rig.run_until([&] { return rig.st(1).boots == 2; }));
    CHECK(le(cn.objects[{0x2001, 0x01}]) == ModuleSettings{}.endat_mode());  // reconfigured
    CHECK(rig.st(2).resets == 0);
  }
  SECTION("a CN asks to stop itself: refused, the cycle goes on") {
    cn.nmt_request = NmtRequest{static_cast<uint8_t>(NmtCommandId::kStopNode), 1, {}};
    REQUIRE(rig.run_until([&] { return rig.st(1).nmt_requests == 1; }, 50));
    for (int i = 0; i < 50; ++i) rig.step();
    CHECK(rig.st(1).nmt_requests_refused == 1);
    CHECK(rig.st(1).last_error == MnError::kNmtRequestRefused);
    CHECK(rig.st(1).resets == 0);
    CHECK(rig.st(1).boot == CnBootState::kOperational);
    CHECK(rig.bus->state() == BusState::Operational);
  }
  SECTION("a CN asks to reset another node: refused") {
    cn.nmt_request = NmtRequest{static_cast<uint8_t>(NmtCommandId::kResetNode), 2, {}};
    REQUIRE(rig.run_until([&] { return rig.st(1).nmt_requests == 1; }, 50));
    for (int i = 0; i < 50; ++i) rig.step();
    CHECK(rig.st(1).nmt_requests_refused == 1);
    CHECK(rig.st(2).resets == 0);
    CHECK(rig.st(1).resets == 0);
  }
}

TEST_CASE("A power-cycled CN is detected and booted again", "[powerlink][mn]") {
  Rig rig({1}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  rig.cns[0]->power_cycle();
  REQUIRE(rig.run_until([&] { return rig.st(1).boot != CnBootState::kOperational; }, 10));
  REQUIRE(rig.run_until([&] { return rig.st(1).boots == 2; }));
  CHECK(rig.cns[0]->state == NmtState::kOperational);
  CHECK(le(rig.cns[0]->objects[{0x2001, 0x01}]) == ModuleSettings{}.endat_mode());  // reconfigured
}

TEST_CASE("StatusResponses with error entries are tolerated and counted", "[powerlink][mn]") {
  Rig rig({1}, 1);
  rig.cns[0]->status_errors = {{0x7001, 0x8235, 7, {}}, {0x7001, 0x8611, 8, {}}};
  rig.cns[0]->exception_new = true;  // signalled: fetched once the handshake is done
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  CHECK(rig.cns[0]->status_requests > 0);
  CHECK(rig.st(1).status_error_entries >= 2);
  CHECK(rig.st(1).last_error_code == 0x8611);
}

TEST_CASE("A PRes of unexpected size is reported, not fatal", "[powerlink][mn]") {
  Rig rig({1}, 1);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  rig.cns[0]->pres_size_delta = 10;  // longer: reported, modules still decoded
  rig.step();
  CHECK(rig.st(1).pres_size_mismatches == 1);
  CHECK(rig.st(1).last_pres_size == pres_module_size(7) + 10);
  CHECK(rig.axes[0].inputs_fresh);
  CHECK(rig.st(1).last_error == MnError::kPresSizeMismatch);
  rig.cns[0]->pres_size_delta = -5;  // shorter: reported, inputs not fresh
  rig.step();
  CHECK(rig.st(1).pres_size_mismatches == 2);
  CHECK_FALSE(rig.axes[0].inputs_fresh);
  CHECK(rig.st(1).boot == CnBootState::kOperational);
  rig.cns[0]->pres_size_delta = 0;
  rig.step();
  CHECK(rig.axes[0].inputs_fresh);
}

TEST_CASE("A CN with the wrong identity is not booted", "[powerlink][mn]") {
  Rig rig({1}, 1);
  // Rebuild with an expected vendor the CN does not have.
  rig.config.bus.nodes[0].vendor_id = 0x77;
  rig.bus = std::make_unique<PowerlinkBus>(rig.config, rig.link);
  rig.bus->set_clock(&fake_clock);
  REQUIRE_FALSE(rig.bus->start());
  for (int i = 0; i < 300; ++i) rig.step();
  CHECK(rig.st(1).boot == CnBootState::kIdentify);
  CHECK(rig.st(1).last_error == MnError::kIdentMismatch);
  CHECK(rig.bus->state() == BusState::Booting);
  const auto status = rig.bus->status();
  CHECK(status.node_count == 1);
  CHECK(status.nodes[0].last_error == MnError::kIdentMismatch);
}

TEST_CASE("The MN's frames decode in the codec with consistent fields", "[powerlink][mn]") {
  Rig rig({1, 2}, 1);
  rig.link.log = true;
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  std::size_t socs = 0, preqs = 0, soas = 0, asnds = 0;
  for (const auto& f : rig.link.sent_log) {
    REQUIRE(f.size() >= kMinFrameSize);
    auto parsed = parse_frame(f);
    REQUIRE(parsed);
    CHECK(parsed->header.src_node == kNodeMn);
    switch (parsed->header.type) {
      case MessageType::kSoC:
        ++socs;
        break;
      case MessageType::kPReq:
        ++preqs;
        break;
      case MessageType::kSoA:
        ++soas;
        break;
      case MessageType::kASnd:
        ++asnds;
        break;
      default:
        FAIL("MN sent a PRes");
    }
  }
  CHECK(soas == rig.cycle);
  CHECK(socs > 0);
  CHECK(socs < rig.cycle);  // the boot started with reduced cycles
  CHECK(preqs > 0);
  CHECK(asnds > 0);
}

#include <unistd.h>

#include "pcap_util.hpp"

TEST_CASE("Wireshark decodes the MN's boot traffic without errors", "[powerlink][mn][tshark]") {
  if (access("/usr/bin/tshark", X_OK) != 0) {
    WARN("tshark not installed: Wireshark decoding check skipped");
    return;
  }
  Rig rig({1}, 1);
  rig.link.log = true;
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  const std::string path = DS1928_TEST_TMPDIR "/powerlink_mn_boot.pcap";
  test::write_pcap(path, rig.link.sent_log);
  const std::string out = test::run_command("tshark -n -r " + path + " -V 2>&1");
  CHECK(out.find("Malformed") == std::string::npos);
  CHECK(out.find("Expert Info (Error") == std::string::npos);
  CHECK(out.find("Expert Info (Warning") == std::string::npos);
  const std::string summary = test::run_command("tshark -n -r " + path + " 2>/dev/null");
  for (const char* what : {"SoC", "PReq", "IDENT_REQUEST", "STATUS_REQUEST", "UNSPEC_INVITE",
                           "NMTEnableReadyToOperate", "NMTStartNode", "WriteByIndex"})
    CHECK(summary.find(what) != std::string::npos);
}

namespace {

// Node 1 carries one X20DS1928; node 2 has no module, 6 raw PRes bytes and a 10-byte PReq.
struct RawRig : Rig {
  TestCn* raw_cn = nullptr;
  RawRig() {
    PowerlinkNodeConfig nc;
    nc.node_id = 2;
    nc.preq_size = 10;
    nc.pres_size = 6;
    config.bus.nodes.push_back(nc);
    // Node 1's PReq gets 4 bytes beyond its module's.
    config.bus.nodes[0].preq_size = static_cast<uint16_t>(cns[0]->layout.preq_size + 4);
    auto layout = make_layout({});
    REQUIRE(layout);
    cns.push_back(std::make_unique<TestCn>(2, *layout));
    raw_cn = cns.back().get();
    raw_cn->pres_extra = {0x0A, 0x1B, 0x2C, 0x3D, 0x4E, 0x5F};
    link.cns.push_back(raw_cn);
    bus = std::make_unique<PowerlinkBus>(config, link);
    bus->set_clock(&fake_clock);
    REQUIRE_FALSE(bus->start());
  }
};

}  // namespace

TEST_CASE("A CN without modules is booted and cycled, its raw PRes is published",
          "[powerlink][mn][raw]") {
  RawRig rig;
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  CHECK(rig.st(2).boot == CnBootState::kOperational);
  CHECK(rig.raw_cn->state == NmtState::kOperational);
  rig.step();
  PresSnapshot snap;
  REQUIRE(rig.bus->pres_snapshot(2, snap));
  CHECK(snap.fresh);
  CHECK(snap.received);
  CHECK(snap.rx_time_ns > 0);
  CHECK(std::vector<uint8_t>(snap.bytes().begin(), snap.bytes().end()) == rig.raw_cn->pres_extra);

  // New bytes from the CN show in the next snapshot; a cycle without its PRes is not fresh but
  // keeps the last bytes.
  rig.raw_cn->pres_extra = {1, 2, 3, 4, 5, 6};
  rig.step();
  REQUIRE(rig.bus->pres_snapshot(2, snap));
  CHECK(std::vector<uint8_t>(snap.bytes().begin(), snap.bytes().end()) == rig.raw_cn->pres_extra);
  const uint64_t cycle = snap.cycle;
  rig.raw_cn->drop_pres = true;
  rig.step();
  REQUIRE(rig.bus->pres_snapshot(2, snap));
  CHECK_FALSE(snap.fresh);
  CHECK(snap.cycle == cycle);
  CHECK(snap.size == 6);
  CHECK(snap.payload[0] == 1);
  CHECK_FALSE(rig.bus->pres_snapshot(3, snap));
}

TEST_CASE("Raw PReq bytes set through the bus reach the CN in every following cycle",
          "[powerlink][mn][raw]") {
  RawRig rig;
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  const std::vector<uint8_t> set = {0xDE, 0xAD, 0xBE};
  const PreqWriteCheck ok = rig.bus->set_preq(2, 7, set);
  REQUIRE_FALSE(ok.error);
  CHECK(ok.preq_size == 10);
  rig.step();
  REQUIRE(rig.raw_cn->last_preq_payload.size() == 10);
  CHECK(rig.raw_cn->last_preq_payload[6] == 0);
  CHECK(rig.raw_cn->last_preq_payload[7] == 0xDE);
  CHECK(rig.raw_cn->last_preq_payload[8] == 0xAD);
  CHECK(rig.raw_cn->last_preq_payload[9] == 0xBE);
  rig.raw_cn->last_preq_payload.clear();
  rig.step();
  REQUIRE(rig.raw_cn->last_preq_payload.size() == 10);
  CHECK(rig.raw_cn->last_preq_payload[8] == 0xAD);

  // Bytes after node 1's module are free; the module's own belong to its axis.
  const uint16_t module_end = rig.cns[0]->layout.preq_size;
  const std::vector<uint8_t> two = {0x55, 0x66};
  REQUIRE_FALSE(rig.bus->set_preq(1, module_end + 1, two).error);
  const PreqWriteCheck overlap = rig.bus->set_preq(1, static_cast<uint16_t>(module_end - 1), two);
  CHECK(overlap.error == make_error_code(MnError::kPreqRegionOwnedByModule));
  CHECK(overlap.module.slot == 1);
  CHECK(rig.bus->set_preq(1, 0, two).error == make_error_code(MnError::kPreqRegionOwnedByModule));
  rig.step();
  const auto& p1 = rig.cns[0]->last_preq_payload;
  REQUIRE(p1.size() == module_end + 4u);
  CHECK(p1[module_end] == 0);
  CHECK(p1[module_end + 1] == 0x55);
  CHECK(p1[module_end + 2] == 0x66);

  // Past the PReq, too long, unknown node.
  const PreqWriteCheck past = rig.bus->set_preq(2, 9, two);
  CHECK(past.error == make_error_code(MnError::kPreqOutOfRange));
  CHECK(past.preq_size == 10);
  CHECK(rig.bus->set_preq(2, 10, std::span<const uint8_t>()).error ==
        std::error_code());  // empty write at the end: nothing to do, accepted
  const std::vector<uint8_t> huge(kMaxPreqWrite + 1, 0);
  CHECK(rig.bus->set_preq(2, 0, huge).error == make_error_code(MnError::kPreqWriteTooLong));
  CHECK(rig.bus->set_preq(9, 0, two).error == make_error_code(MnError::kNodeNotConfigured));
  rig.step();
  CHECK(rig.raw_cn->last_preq_payload[9] == 0xBE);  // the refused writes changed nothing

  // A re-booted CN gets the set bytes again (the MN clears its PReq image on identification).
  rig.raw_cn->power_cycle();
  REQUIRE(rig.run_until([&] { return rig.st(2).boots == 2; }));
  rig.step();
  REQUIRE(rig.raw_cn->last_preq_payload.size() == 10);
  CHECK(rig.raw_cn->last_preq_payload[7] == 0xDE);
}

TEST_CASE("a module at an overridden PRes/PReq offset is decoded from and encoded at it",
          "[powerlink][mn][layout]") {
  // Slot 2 moved past a gap; slot 1 keeps its default place (0 in both payloads).
  static constexpr uint16_t kPresAt = 60;
  static constexpr uint16_t kPreqAt = 30;
  Rig rig({1}, 2, [](AxisConfig& a) {
    if (a.slot == 2) {
      a.pres_offset = kPresAt;
      a.preq_offset = kPreqAt;
    }
  });
  const NodeImageLayout* layout = rig.bus->managing_node().layout(1);
  REQUIRE(layout);
  REQUIRE(layout->find(2));
  CHECK(layout->find(1)->pres_offset == 0);
  CHECK(layout->find(2)->pres_offset == kPresAt);
  CHECK(layout->find(2)->preq_offset == kPreqAt);
  CHECK(layout->pres_size == kPresAt + pres_module_size(7));
  CHECK(layout->preq_size == kPreqAt + preq_module_size(7));

  TestCn& cn = *rig.cns[0];
  cn.inputs.position_lw = 0xCAFE;
  cn.inputs.position_hw = 0x1234;
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  rig.axes[0].outputs.output_sequence = 0x11;
  rig.axes[1].outputs.output_sequence = 0x5A;
  rig.axes[1].outputs.tx_bytes[0] = 0x77;
  rig.axes[1].outputs.ack_error_info = 0x03;
  auto r = rig.step();
  REQUIRE(r.bus_up);
  // Slot 2's inputs come from bytes 60.. of the PRes; the default place (23..) holds zeros.
  REQUIRE(rig.axes[1].inputs_fresh);
  CHECK(rig.axes[1].inputs.position_lw == 0xCAFE);
  CHECK(rig.axes[1].inputs.position_hw == 0x1234);
  // Slot 2's outputs went to bytes 30.. of the PReq, slot 1's to 0...
  const std::vector<uint8_t>& preq = cn.last_preq_payload;
  REQUIRE(preq.size() >= kPreqAt + preq_module_size(7));
  CHECK(preq[0] == 0x11);
  CHECK(preq[kPreqAt] == 0x5A);
  CHECK(preq[kPreqAt + 1] == 0x77);
  CHECK(preq[kPreqAt + 1 + 7] == 0x03);
  // ... and nothing at slot 2's default place (9..).
  CHECK(preq[preq_module_size(7)] == 0);
}

TEST_CASE("overlapping or oversized module blocks are refused, naming the slots",
          "[powerlink][mn][layout]") {
  SECTION("make_layout: overlap in the PRes") {
    LayoutIssue issue;
    const std::array specs{ModuleSpec{1, 7, 7}, ModuleSpec{2, 7, 7, uint16_t{22}, std::nullopt}};
    auto layout = make_layout(specs, &issue);
    REQUIRE_FALSE(layout);
    CHECK(layout.error() == make_error_code(MnError::kModuleBlocksOverlap));
    CHECK(issue.slot == 2);
    CHECK(issue.other_slot == 1);
    CHECK_FALSE(issue.in_preq);
    // Adjacent (ends where the other starts) is fine.
    const std::array ok{ModuleSpec{1, 7, 7}, ModuleSpec{2, 7, 7, uint16_t{23}, uint16_t{9}}};
    CHECK(make_layout(ok));
  }
  SECTION("make_layout: overlap in the PReq") {
    LayoutIssue issue;
    const std::array specs{ModuleSpec{3, 7, 7, std::nullopt, uint16_t{100}},
                           ModuleSpec{5, 7, 7, std::nullopt, uint16_t{105}}};
    auto layout = make_layout(specs, &issue);
    REQUIRE_FALSE(layout);
    CHECK(layout.error() == make_error_code(MnError::kModuleBlocksOverlap));
    CHECK(issue.slot == 5);
    CHECK(issue.other_slot == 3);
    CHECK(issue.in_preq);
  }
  SECTION("make_layout: block past 1490 bytes") {
    LayoutIssue issue;
    const std::array specs{ModuleSpec{1, 7, 7, uint16_t{1480}, std::nullopt}};
    auto layout = make_layout(specs, &issue);
    REQUIRE_FALSE(layout);
    CHECK(layout.error() == make_error_code(MnError::kModuleBlockOutsidePayload));
    CHECK(issue.slot == 1);
  }
  auto construct = [](const std::function<void(PowerlinkNodeConfig&)>& node,
                      const std::function<void(AxisConfig&)>& place) -> std::string {
    MnConfig config;
    PowerlinkNodeConfig nc;
    nc.node_id = 4;
    if (node) node(nc);
    config.bus.nodes.push_back(nc);
    for (uint8_t s = 1; s <= 2; ++s) {
      AxisConfig a;
      a.node = 4;
      a.slot = s;
      place(a);
      config.axes.push_back(a);
    }
    try {
      ManagingNode mn(config);
    } catch (const std::system_error& e) {
      return std::string(e.code().category().name()) + "/" + std::to_string(e.code().value()) +
             ": " + e.what();
    }
    return "constructed";
  };
  SECTION("ManagingNode: overlap names both slots") {
    const std::string what = construct({}, [](AxisConfig& a) {
      if (a.slot == 1) a.preq_offset = 4;
    });
    CHECK_THAT(what,
               Catch::StartsWith(std::string(mn_category().name()) + "/" +
                                 std::to_string(static_cast<int>(MnError::kModuleBlocksOverlap))));
    CHECK_THAT(what, Catch::Contains("node 4, PReq: slot 2 and slot 1"));
  }
  SECTION("ManagingNode: a block past the configured pres_size") {
    const std::string what = construct([](PowerlinkNodeConfig& n) { n.pres_size = 60; },
                                       [](AxisConfig& a) {
                                         if (a.slot == 2) a.pres_offset = 40;
                                       });
    CHECK_THAT(what, Catch::Contains("slot 2 ends past the configured pres_size 60"));
    CHECK_THAT(what, Catch::StartsWith(
                         std::string(mn_category().name()) + "/" +
                         std::to_string(static_cast<int>(MnError::kModuleBlockOutsidePayload))));
  }
  SECTION("ManagingNode: non-overlapping overrides construct") {
    CHECK(construct({}, [](AxisConfig& a) {
            if (a.slot == 1) a.pres_offset = 100;
          }) == "constructed");
  }
}

TEST_CASE("MN writes the configured EnDatInfoCmd channels at boot, and only those",
          "[powerlink][mn][info]") {
  Rig rig({1}, 2, [](AxisConfig& a) {
    if (a.slot != 2) return;
    a.module.info_cmd[0] = 0x0000'4C08;  // temperature 1
    a.module.info_cmd[2] = 0x0301'A506;  // a blocked parameter
  });
  TestCn& cn = *rig.cns[0];
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  // EnDatInfoCmd01..04 are subindices 0x12..0x15 of the slot's object (docs/registers.md).
  CHECK(cn.objects[{0x2002, 0x12}].size() == 4);
  CHECK(le(cn.objects[{0x2002, 0x12}]) == 0x0000'4C08u);
  CHECK(le(cn.objects[{0x2002, 0x14}]) == 0x0301'A506u);
  CHECK(cn.objects.count({0x2002, 0x13}) == 0);  // off: not written
  CHECK(cn.objects.count({0x2001, 0x12}) == 0);  // slot 1 has none
  CHECK(cn.objects.size() == 32);                // the boot's 30 and the two channels
}

TEST_CASE(
    "The MN listens NOT_ACTIVE for MNWaitNotAct first and stays there when another MN is heard",
    "[powerlink][mn][nmt]") {
  auto config_with_wait = [](uint32_t wait_ms, uint8_t mac_last) {
    MnConfig c;
    PowerlinkNodeConfig nc;
    nc.node_id = 1;
    c.bus.nodes.push_back(nc);
    c.bus.nmt.wait_not_active_ms = wait_ms;
    c.mac = {0x02, 0, 0, 0, 0, mac_last};
    return c;
  };
  // Another MN's SoC, as it would come over the wire.
  ManagingNode other(config_with_wait(0, 0x99));
  other.begin_cycle(0);
  std::array<uint8_t, kMaxFrameSize> soc{};
  const auto soc_len = other.build_soc(soc);
  REQUIRE(soc_len);
  const std::span<const uint8_t> foreign(soc.data(), *soc_len);
  constexpr int64_t kMs = 1'000'000;

  ManagingNode mn(config_with_wait(10, 0x01));
  auto run_until = [&](int64_t& t, int64_t end_ms) {
    for (; t <= end_ms * kMs; t += kMs) {
      mn.begin_cycle(t);
      if (mn.not_active()) mn.not_active_cycle();
    }
  };
  int64_t t = 0;
  CHECK(mn.mn_state() == NmtState::kNotActive);
  SECTION("silence for MNWaitNotAct: PRE_OPERATIONAL_1") {
    run_until(t, 9);
    CHECK(mn.not_active());
    CHECK_FALSE(mn.full_cycle());
    run_until(t, 11);
    CHECK(mn.mn_state() == NmtState::kPreOperational1);
    CHECK(mn.counters().foreign_mn_frames == 0);
  }
  SECTION("another MN's SoC while listening: NOT_ACTIVE for good, the sender named") {
    run_until(t, 5);
    CHECK_FALSE(mn.on_frame(foreign));
    run_until(t, 100);
    CHECK(mn.mn_state() == NmtState::kNotActive);
    CHECK(mn.counters().foreign_mn_at_start);
    CHECK(mn.counters().foreign_mn_frames == 1);
    CHECK(mn.counters().foreign_mn_frame == MessageType::kSoC);
    CHECK(mn.counters().foreign_mn_mac == MacAddress{0x02, 0, 0, 0, 0, 0x99});
  }
  SECTION("another MN's SoC once running: counted and named, the MN runs on") {
    run_until(t, 20);
    REQUIRE(mn.mn_state() != NmtState::kNotActive);
    CHECK_FALSE(mn.on_frame(foreign));
    run_until(t, 30);
    CHECK(mn.mn_state() != NmtState::kNotActive);
    CHECK_FALSE(mn.counters().foreign_mn_at_start);
    CHECK(mn.counters().foreign_mn_frames == 1);
  }
  SECTION("MNWaitNotAct 0: no listening") {
    ManagingNode at_once(config_with_wait(0, 0x01));
    CHECK(at_once.mn_state() == NmtState::kPreOperational1);
  }
}
