// The MN as a configuration manager for third-party CNs: object writes in the boot step
// "configure" with per-object abort reports, the identity read back by SDO, the cycle objects,
// READY_TO_OPERATE before OPERATIONAL/RD, and exception signalling (EN/EA/ER). In-memory CN rig.
#include <algorithm>
#include <catch2/catch.hpp>

#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "test_cn.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;
using test::Rig;
using test::TestCn;

namespace {

std::vector<uint8_t> le(uint64_t v, int n) {
  std::vector<uint8_t> d;
  for (int i = 0; i < n; ++i) d.push_back(static_cast<uint8_t>(v >> (8 * i)));
  return d;
}

bool operational(Rig& rig) {
  return rig.bus->state() == BusState::Operational;
}

}  // namespace

TEST_CASE(
    "The MN goes OPERATIONAL and sets PReq RD only after the mandatory CNs confirm "
    "READY_TO_OPERATE",
    "[powerlink][mn][nmt]") {
  Rig rig({1, 2});
  rig.cns[1]->hold_ready_to_operate = true;  // node 2 has not confirmed yet
  REQUIRE(rig.run_until([&] { return rig.st(2).boot == CnBootState::kWaitReadyToOperate; }));
  for (int i = 0; i < 200; ++i) rig.step();
  CHECK(rig.cns[1]->state == NmtState::kPreOperational2);
  CHECK(rig.bus->managing_node().mn_state() == NmtState::kPreOperational2);
  CHECK_FALSE(rig.cns[0]->last_preq_ready);
  CHECK_FALSE(rig.cns[1]->last_preq_ready);
  CHECK(rig.st(1).boot == CnBootState::kWaitReadyToOperate);
  // Confirmed: now the MN goes on, and both CNs are started.
  rig.cns[1]->hold_ready_to_operate = false;
  rig.cns[1]->state = NmtState::kReadyToOperate;
  REQUIRE(rig.run_until([&] { return operational(rig); }));
  rig.step();
  CHECK(rig.bus->managing_node().mn_state() == NmtState::kOperational);
  CHECK(rig.cns[0]->last_preq_ready);
  CHECK(rig.cns[1]->state == NmtState::kOperational);
}

TEST_CASE(
    "A generic CN gets its configured objects in order, a refused object is reported with "
    "its abort code and the boot goes on",
    "[powerlink][mn][configure]") {
  Rig rig({7}, 0, {}, [](PowerlinkNodeConfig& n) {
    n.object_writes = {{0x1006, 0, le(1000, 4), true},
                       {0x1A00, 0, {0}, true},
                       {0x1A00, 1, le(0x0040'0000'0001'6000ULL, 8), true},
                       {0x1A00, 0, {1}, true},
                       {0x1C14, 0, le(50000, 4), false}};
    n.pres_size = 8;
  });
  rig.cns[0]->write_aborts[{0x1C14, 0}] = 0x06090030;  // value range exceeded
  REQUIRE(rig.run_until([&] { return operational(rig); }));
  using Key = std::pair<uint16_t, uint8_t>;
  CHECK(rig.cns[0]->writes ==
        std::vector<Key>{{0x1006, 0}, {0x1A00, 0}, {0x1A00, 1}, {0x1A00, 0}, {0x1C14, 0}});
  CHECK(rig.cns[0]->objects[{0x1006, 0}] == le(1000, 4));
  CHECK(rig.cns[0]->objects[{0x1A00, 0}] == std::vector<uint8_t>{1});
  const CnStatus& st = rig.st(7);
  CHECK(st.objects_written == 4);
  CHECK(st.object_failures == 1);
  REQUIRE(st.last_failure_count == 1);
  CHECK(st.last_failures[0].index == 0x1C14);
  CHECK(st.last_failures[0].subindex == 0);
  CHECK_FALSE(st.last_failures[0].read);
  CHECK(st.last_failures[0].error == make_sdo_abort_error(0x06090030));
  // Nothing else: no module registers, no reads, for a CN without X20DS1928.
  CHECK(rig.cns[0]->reads == 0);
  CHECK(st.boot == CnBootState::kOperational);
}

TEST_CASE("cycle_objects: the MN writes the CN's cycle length and payload limits",
          "[powerlink][mn][configure]") {
  Rig rig({3}, 1, {}, [](PowerlinkNodeConfig& n) { n.cycle_objects = true; });
  REQUIRE(rig.run_until([&] { return operational(rig); }));
  auto& o = rig.cns[0]->objects;
  CHECK(o[{0x1006, 0}] == le(1000, 4));
  CHECK(o[{0x1F98, 4}] == le(rig.st(3).preq_size, 2));
  CHECK(o[{0x1F98, 5}] == le(rig.st(3).pres_size, 2));
  CHECK(rig.st(3).pres_size == 16 + 7);
}

TEST_CASE("Objects written in the boot are taken by NMTResetConfiguration before the CN is started",
          "[powerlink][mn][configure]") {
  // EPSG DS 301: a configuration download ends with NMTResetConfiguration; the CN takes the
  // objects on re-entering its boot (RESET_CONFIGURATION -> NOT_ACTIVE), is identified again and
  // started without a second download.
  Rig rig({3}, 1, {}, [](PowerlinkNodeConfig& n) { n.cycle_objects = true; });
  rig.config.bus.nodes[0].multiplexed = true;
  rig.config.bus.multiplex_cycles = 2;
  rig.rebuild();
  REQUIRE(rig.run_until([&] { return operational(rig); }, 5000));
  TestCn& cn = *rig.cns[0];
  const std::vector<NmtCommandId> boot{NmtCommandId::kResetConfiguration,
                                       NmtCommandId::kEnableReadyToOperate,
                                       NmtCommandId::kStartNode};
  CHECK(cn.nmt_log == boot);
  CHECK(rig.st(3).configuration_resets == 1);
  CHECK(rig.st(3).resets == 0);
  CHECK(rig.st(3).boots == 1);
  // What the CN took at RESET_CONFIGURATION: the cycle objects and MultiplCycleCnt (0x1F98/7),
  // the interval in which the MN polls it.
  CHECK(cn.taken[{0x1006, 0}] == le(1000, 4));
  CHECK(cn.taken[{0x1F98, 5}] == le(rig.st(3).pres_size, 2));
  CHECK(cn.taken[{0x1F98, 7}] == std::vector<uint8_t>{2});
  // Written once: the second pass of "configure" writes nothing.
  const auto writes_of_1006 =
      std::count(cn.writes.begin(), cn.writes.end(), std::pair<uint16_t, uint8_t>{0x1006, 0});
  CHECK(writes_of_1006 == 1);

  // NMTResetNode restores the CN's stored objects: the next boot writes and resets again.
  cn.drop_pres = true;
  REQUIRE(rig.run_until([&] { return rig.st(3).resets == 1; }, 200));
  cn.drop_pres = false;
  REQUIRE(rig.run_until([&] { return rig.st(3).boots == 2; }, 5000));
  CHECK(rig.st(3).configuration_resets == 2);
  CHECK(std::count(cn.writes.begin(), cn.writes.end(), std::pair<uint16_t, uint8_t>{0x1006, 0}) ==
        2);
}

namespace {
// A download that carries its configuration date and time (0x1020/1, /2), as openCONFIGURATOR's
// concise DCF does, with the MN expecting them (0x1F26/0x1F27 of its CDC).
constexpr uint32_t kConfDate = 0x3124;
constexpr uint32_t kConfTime = 0x03735955;
void dated_download(PowerlinkNodeConfig& n) {
  n.cycle_objects = true;
  n.object_writes = {{0x1020, 1, le(kConfDate, 4), true}, {0x1020, 2, le(kConfTime, 4), true}};
  n.expected_conf_date = kConfDate;
  n.expected_conf_time = kConfTime;
}
long writes_of(const TestCn& cn, uint16_t index, uint8_t sub) {
  return std::count(cn.writes.begin(), cn.writes.end(), std::pair<uint16_t, uint8_t>{index, sub});
}
}  // namespace

TEST_CASE("A CN that took the download reports the expected configuration date: written once",
          "[powerlink][mn][configure]") {
  Rig rig({3}, 1, {}, dated_download);
  REQUIRE(rig.run_until([&] { return operational(rig); }, 5000));
  CHECK(rig.st(3).configuration_resets == 1);
  CHECK(rig.st(3).configuration_not_verified == 0);
  CHECK(writes_of(*rig.cns[0], 0x1006, 0) == 1);
  CHECK(rig.cns[0]->taken[{0x1020, 1}] == le(kConfDate, 4));
}

TEST_CASE(
    "A CN power-cycled while it resets its configuration is not started with its defaults: the "
    "MN sees the configuration date differ and writes it again",
    "[powerlink][mn][configure]") {
  Rig rig({3}, 1, {}, dated_download);
  TestCn& cn = *rig.cns[0];
  cn.power_cycles_in_reset_configuration = 1;  // the download is lost in the first reset
  REQUIRE(rig.run_until([&] { return operational(rig); }, 5000));
  const CnStatus& st = rig.st(3);
  CHECK(st.configuration_not_verified == 1);
  CHECK(st.configuration_resets == 2);
  CHECK(st.resets == 0);
  CHECK(st.boots == 1);
  CHECK_FALSE(st.last_error);  // said while it lasted, cleared once the node runs
  // Written twice, and what the CN runs with is the download: its cycle length, the date.
  CHECK(writes_of(cn, 0x1006, 0) == 2);
  CHECK(writes_of(cn, 0x1020, 1) == 2);
  CHECK(cn.taken[{0x1006, 0}] == le(1000, 4));
  CHECK(cn.taken[{0x1020, 2}] == le(kConfTime, 4));
}

TEST_CASE(
    "A CN that never reports the expected configuration date is never started, the reason is in "
    "status",
    "[powerlink][mn][configure]") {
  Rig rig({3}, 1, {}, dated_download);
  TestCn& cn = *rig.cns[0];
  cn.write_aborts[{0x1020, 2}] = 0x06010002;  // read-only here: the time stays 0
  REQUIRE(rig.run_until([&] { return rig.st(3).configuration_not_verified >= 3; }, 20000));
  CHECK(rig.st(3).boot != CnBootState::kOperational);
  CHECK(rig.st(3).boots == 0);
  CHECK(cn.state != NmtState::kOperational);
  CHECK(rig.st(3).last_error == make_error_code(MnError::kConfigurationNotVerified));
  CHECK(rig.st(3).configuration_resets >= 3);
}

TEST_CASE(
    "A reset during an open SDO transfer keeps its own reason: the transfer it ends does not "
    "overwrite the node's last error",
    "[powerlink][mn][configure]") {
  Rig rig({7}, 0, {}, [](PowerlinkNodeConfig& n) {
    n.object_writes = {{0x1006, 0, le(1000, 4), true}};
    n.pres_size = 8;
  });
  TestCn& cn = *rig.cns[0];
  cn.ignore_sdo = true;  // the configuration download stays open
  REQUIRE(rig.run_until([&] { return rig.st(7).boot == CnBootState::kConfigure; }));
  for (int i = 0; i < 5; ++i) rig.step();
  REQUIRE(rig.st(7).boot == CnBootState::kConfigure);
  cn.drop_pres = true;  // two PRes lost in a row: the loss-of-PRes threshold (15) fires
  REQUIRE(rig.run_until([&] { return rig.st(7).resets > 0; }));
  CHECK(rig.st(7).last_reset_reason == MnError::kLossOfPresThreshold);
  CHECK(rig.st(7).last_error == MnError::kLossOfPresThreshold);
  CHECK(rig.st(7).sdo_errors == 0);  // the download was the MN's own, not a client's request
}

TEST_CASE("A CN with nothing to write is started without NMTResetConfiguration",
          "[powerlink][mn][configure]") {
  Rig rig({3}, 0);
  REQUIRE(rig.run_until([&] { return operational(rig); }, 5000));
  const std::vector<NmtCommandId> boot{NmtCommandId::kEnableReadyToOperate,
                                       NmtCommandId::kStartNode};
  CHECK(rig.cns[0]->nmt_log == boot);
  CHECK(rig.st(3).configuration_resets == 0);
}

TEST_CASE("The identity is read back by SDO, a mismatch names the object, expected and found",
          "[powerlink][mn][identity]") {
  SECTION("matching identity boots") {
    Rig rig({4}, 0, {}, [](PowerlinkNodeConfig& n) {
      n.device_type = 0x000F0191;
      n.serial_no = 0x12345678;
    });
    rig.cns[0]->device_type = 0x000F0191;
    rig.cns[0]->serial_no = 0x12345678;
    rig.cns[0]->objects[{0x1000, 0}] = le(0x000F0191, 4);
    rig.cns[0]->objects[{0x1018, 4}] = le(0x12345678, 4);
    REQUIRE(rig.run_until([&] { return operational(rig); }));
    CHECK(rig.cns[0]->reads == 2);
    CHECK_FALSE(rig.st(4).identity_mismatch);
  }
  SECTION("a different product code stops the boot") {
    Rig rig({4}, 0, {}, [](PowerlinkNodeConfig& n) { n.product_code = 0x1928; });
    rig.cns[0]->objects[{0x1018, 2}] = le(0x2928, 4);
    REQUIRE(rig.run_until([&] { return rig.st(4).identity_mismatch; }));
    const CnStatus& st = rig.st(4);
    CHECK(st.mismatch.index == 0x1018);
    CHECK(st.mismatch.subindex == 2);
    CHECK(st.mismatch.expected == 0x1928);
    CHECK(st.mismatch.found == 0x2928);
    CHECK_FALSE(st.mismatch.unreadable);
    CHECK(st.last_reset_reason == make_error_code(MnError::kIdentityCheckFailed));
    for (int i = 0; i < 500; ++i) rig.step();
    CHECK(st.boots == 0);
    CHECK(rig.cns[0]->state != NmtState::kOperational);
  }
  SECTION("an identity object the CN does not have is reported as unreadable") {
    Rig rig({4}, 0, {}, [](PowerlinkNodeConfig& n) { n.revision_no = 0; });
    rig.cns[0]->objects.erase({0x1018, 3});
    REQUIRE(rig.run_until([&] { return rig.st(4).identity_mismatch; }));
    CHECK(rig.st(4).mismatch.unreadable);
    REQUIRE(rig.st(4).last_failure_count >= 1);
    CHECK(rig.st(4).last_failures[0].read);
    CHECK(rig.st(4).last_failures[0].error == make_sdo_abort_error(0x06020000));
  }
}

TEST_CASE(
    "Exception signalling: EN from an OPERATIONAL CN makes the MN fetch its error entries "
    "and acknowledge with EA",
    "[powerlink][mn][exception]") {
  Rig rig({1});
  REQUIRE(rig.run_until([&] { return operational(rig); }));
  TestCn& cn = *rig.cns[0];
  CHECK(cn.exception_resets >= 1);  // ER at the start of the boot
  const int requests = cn.status_requests;
  const uint32_t entries = rig.st(1).status_error_entries;
  for (int i = 0; i < 50; ++i) rig.step();
  CHECK(cn.status_requests == requests);  // no polling of an OPERATIONAL CN without EN
  ErrorEntry entry;
  entry.type = 0x1001;
  entry.code = 0x8611;
  cn.status_errors = {entry};
  cn.exception_new = true;
  REQUIRE(rig.run_until([&] { return cn.last_preq_ea; }, 50));
  CHECK(cn.status_requests == requests + 1);
  CHECK(rig.st(1).status_error_entries == entries + 1);
  CHECK(rig.st(1).last_error_code == 0x8611);
  CHECK(rig.st(1).exceptions_signalled == 1);
  // Acknowledged: no more requests until EN toggles again.
  for (int i = 0; i < 50; ++i) rig.step();
  CHECK(cn.status_requests == requests + 1);
  cn.exception_new = false;
  REQUIRE(rig.run_until([&] { return !cn.last_preq_ea; }, 50));
  CHECK(cn.status_requests == requests + 2);
  CHECK(rig.st(1).boot == CnBootState::kOperational);
}

TEST_CASE("Error signalling handshake: ER=1 until EC=1, then ER=0 until EC=0",
          "[powerlink][mn][exception]") {
  Rig rig({1});
  REQUIRE(rig.run_until([&] { return operational(rig); }));
  const TestCn& cn = *rig.cns[0];
  REQUIRE(cn.er_seen.size() >= 2);
  // ER=1 first, then ER=0 (no ER=1 after the first ER=0: the handshake completed once).
  // The handshake runs after every identification: again after NMTResetConfiguration (the CN
  // reset, EC=1 again), so once more per configuration reset.
  CHECK(cn.er_seen.front());
  const auto last_one = std::find(cn.er_seen.rbegin(), cn.er_seen.rend(), true);
  REQUIRE(last_one != cn.er_seen.rend());
  const auto after = last_one.base();  // the first ER=0 after the last ER=1
  REQUIRE(after != cn.er_seen.end());
  CHECK(std::find(after, cn.er_seen.end(), true) == cn.er_seen.end());
  CHECK(rig.st(1).errsig == ErrSigState::kReady);
  CHECK(rig.st(1).errsig_handshakes == 1 + rig.st(1).configuration_resets);
  CHECK(rig.st(1).errsig_gave_up == 0);
  CHECK(rig.st(1).resets == 0);
}

TEST_CASE("A CN that never answers EC=1 still boots, the MN gives up on the handshake once",
          "[powerlink][mn][exception]") {
  Rig rig({1});
  rig.cns[0]->follow_er = false;
  REQUIRE(rig.run_until([&] { return operational(rig); }));
  REQUIRE(rig.run_until([&] { return rig.st(1).errsig == ErrSigState::kGaveUp; }, 2000));
  CHECK(rig.st(1).errsig_gave_up == 1);
  CHECK(rig.st(1).errsig_handshakes == 0);
  const int requests = rig.cns[0]->status_requests;
  // Bounded: per identification (the first, and after each NMTResetConfiguration).
  CHECK(requests <= static_cast<int>((1 + rig.st(1).configuration_resets) *
                                     (MnErrorSignalling::kMaxAttempts + 12)));
  for (int i = 0; i < 200; ++i) rig.step();
  CHECK(rig.cns[0]->status_requests == requests);  // no further handshake requests
  CHECK(rig.st(1).boot == CnBootState::kOperational);
  CHECK(rig.st(1).resets == 0);
  // Its EN toggles are still fetched.
  ErrorEntry entry;
  entry.type = 0x7001;
  entry.code = 0x4242;
  rig.cns[0]->status_errors = {entry};
  rig.cns[0]->exception_new = true;
  REQUIRE(rig.run_until([&] { return rig.cns[0]->last_preq_ea; }, 100));
  CHECK(rig.st(1).last_error_code == 0x4242);
  REQUIRE(rig.st(1).error_entry_count == 1);
  CHECK(rig.st(1).error_entries[0].code == 0x4242);
}

TEST_CASE("The MN's SDO frames keep to AsyncMTU: a long download goes in segments that fit",
          "[powerlink][mn][configure][budget]") {
  // 600 bytes to one object: at AsyncMTU 300 no ASnd of the MN is longer than 314 bytes with its
  // Ethernet header (the cycle budget counts one of them); at 1500 the download is one frame.
  std::vector<uint8_t> domain(600);
  for (std::size_t i = 0; i < domain.size(); ++i) domain[i] = static_cast<uint8_t>(i * 7);
  for (const uint16_t mtu : {uint16_t{300}, uint16_t{1500}}) {
    Rig rig({3}, 1, {}, [&](PowerlinkNodeConfig& n) {
      n.object_writes = {{0x2010, 0x7F, domain, false}};
    });
    rig.config.bus.async_mtu = mtu;
    rig.rebuild();
    std::size_t longest = 0, downloads = 0;
    rig.link.on_send = [&](std::span<const uint8_t> f) {
      const auto frame = parse_frame(f);
      if (!frame || frame->header.src_node != kNodeMn) return;
      const auto* a = std::get_if<Asnd>(&frame->message);
      if (!a || a->service != AsndService::kSdo) return;
      longest = std::max(longest, f.size());
      ++downloads;
    };
    REQUIRE(rig.run_until([&] { return operational(rig); }, 5000));
    CHECK(rig.cns[0]->objects[{0x2010, 0x7F}] == domain);
    INFO("AsyncMTU " << mtu << ": " << downloads << " SDO frames, the longest " << longest);
    if (mtu == 300) {
      CHECK(longest <= 314);
      CHECK(longest >= 300);  // the segments fill the frame
    } else {
      CHECK(longest > 600);
    }
  }
}
