// EnDat commands end to end: socket → EnDatService → CycleWork's Flatstream tunnel → simulated
// module → EnDat bridge → simulated encoder → back, with the cycle thread running.
#include <catch2/catch.hpp>
#include <map>
#include <set>

#include "ds1928/shm.hpp"
#include "rig.hpp"
#include "x20ds1928/module_image.hpp"

using namespace ds1928;
using namespace ds1928::endat_test;
using control::test::error_code_of;
using control::test::LineClient;

namespace {

constexpr int kClientTimeoutMs = 20000;

uint64_t publish_count(const std::string& shm_name) {
  ShmReader reader;
  if (reader.open(shm_name)) return 0;
  return ds1928_shm_publish_count(&reader.header());
}

}  // namespace

TEST_CASE("ident, read-param, write-param round trip and protected write over the socket",
          "[endat_e2e]") {
  Rig rig;
  REQUIRE(rig.wait_identified());
  LineClient c(rig.socket_path(), kClientTimeoutMs);
  REQUIRE(c.connected());
  const uint64_t published_before = publish_count(rig.shm_name());

  const json ident = c.request({{"cmd", "endat-ident"}, {"axis", 0}});
  INFO(ident.dump());
  REQUIRE(ident.value("ok", false));
  CHECK(ident["source"] == "registers");
  CHECK(ident["identification"]["endat"] == "2.2");
  CHECK(ident["identification"]["type"] == "rotary");
  CHECK(ident["identification"]["position_bits"] == 37);
  CHECK(ident["identification"]["steps_per_revolution"] == (1u << 25));
  CHECK(ident["identification"]["revolutions"] == 4096);
  CHECK(ident["identification"]["id"] == "1080790-02");
  CHECK(ident["identification"]["serial"] == "S36845217");

  // The same words read over Flatstream agree with the registers (word 13 = position bits).
  const json bits =
      c.request({{"cmd", "endat-read-param"}, {"axis", 0}, {"mrs", "0xA1"}, {"param", 13}});
  INFO(bits.dump());
  REQUIRE(bits.value("ok", false));
  CHECK(bits["value"] == ident["words"]["13"]["value"]);
  CHECK(bits["area"] == "manufacturer parameters, page 0 (words 0-15)");
  CHECK(bits.value("meaning", "").find("37") != std::string::npos);

  // OEM area: write, read back, read again.
  const json w = c.request({{"cmd", "endat-write-param"},
                            {"axis", 0},
                            {"mrs", 0xA9},
                            {"param", "3"},
                            {"value", "0xBEEF"}});
  INFO(w.dump());
  REQUIRE(w.value("ok", false));
  CHECK(w["value"] == 0xBEEF);
  CHECK(w["verified"] == true);
  const json r = c.request({{"cmd", "endat-read-param"}, {"axis", 0}, {"mrs", 0xA9}, {"param", 3}});
  REQUIRE(r.value("ok", false));
  CHECK(r["value"] == 0xBEEF);
  CHECK(r["value_hex"] == "0xBEEF");

  // Block-addressed area (MRS 0xB1, 4 blocks of 16 words): the reply names block and parameter.
  const json blk = c.request(
      {{"cmd", "endat-read-block"}, {"axis", 0}, {"mrs", 0xB1}, {"block", 2}, {"param", 5}});
  INFO(blk.dump());
  REQUIRE(blk.value("ok", false));
  CHECK(blk["command"] == "read-block");
  CHECK(blk["mrs"] == 0xB1);
  CHECK(blk["block"] == 2);
  CHECK(blk["param"] == 5);
  CHECK(blk["value"] == 0);
  CHECK_FALSE(blk.contains("verified"));

  // Manufacturer page: the encoder keeps its word; the read-back shows it.
  const json p = c.request(
      {{"cmd", "endat-write-param"}, {"axis", 0}, {"mrs", 0xA1}, {"param", 13}, {"value", 0x1234}});
  INFO(p.dump());
  CHECK_FALSE(p.value("ok", true));
  CHECK(error_code_of(p) == "write_rejected");
  CHECK(control::test::error_message_of(p).find("0x0025") != std::string::npos);  // 37 read back

  // Dump of the OEM area carries the written word.
  const json d = c.request({{"cmd", "endat-dump"}, {"axis", 0}, {"mrs", "0xA9"}});
  INFO(d.dump());
  REQUIRE(d.value("ok", false));
  REQUIRE(d["words"].size() == 16);
  CHECK(d["words"][3]["value"] == 0xBEEF);

  // Additional information and the other commands.
  const json info =
      c.request({{"cmd", "endat-read-info"}, {"axis", 0}, {"word", 1}, {"mrs", "0x4C"}});
  INFO(info.dump());
  REQUIRE(info.value("ok", false));
  CHECK(info.value("meaning", "").find("41.5") != std::string::npos);
  CHECK(c.request({{"cmd", "endat-ack"}, {"axis", 0}}).value("ok", false));
  CHECK(c.request({{"cmd", "endat-reset"}, {"axis", 0}}).value("ok", false));

  // Bad arguments are named.
  const json bad =
      c.request({{"cmd", "endat-read-param"}, {"axis", 0}, {"mrs", "0xZZ"}, {"param", 1}});
  CHECK(error_code_of(bad) == "bad_argument");
  const json area =
      c.request({{"cmd", "endat-read-param"}, {"axis", 0}, {"mrs", 0x41}, {"param", 1}});
  CHECK(error_code_of(area) == "bad_argument");  // additional-information code, not a memory area
  const json axis = c.request({{"cmd", "endat-ident"}, {"axis", 7}});
  CHECK(error_code_of(axis) == "bad_argument");
  CHECK_THAT(control::test::error_message_of(axis),
             Catch::Contains("axis 7 does not exist; the configured axis is 0"));
  // A parameter past the end of an area the specification sizes is a range error, not a
  // command to the encoder.
  const uint64_t sent = rig.counters().commands_sent;
  const json page = c.request({{"cmd", "endat-read-param"}, {"mrs", 0xA1}, {"param", 99}});
  CHECK(error_code_of(page) == "bad_argument");
  CHECK_THAT(control::test::error_message_of(page),
             Catch::Contains("99 is outside MRS 0xA1") && Catch::Contains("0..15"));
  const json status_word =
      c.request({{"cmd", "endat-write-param"}, {"mrs", 0xB9}, {"param", 4}, {"value", 0}});
  CHECK(error_code_of(status_word) == "bad_argument");
  CHECK_THAT(control::test::error_message_of(status_word), Catch::Contains("0..3"));
  CHECK(rig.counters().commands_sent == sent);
  CHECK(c.request({{"cmd", "endat-read-param"}, {"mrs", 0xA1}, {"param", 15}}).value("ok", false));

  // Positions kept flowing: the cycle published all along.
  CHECK(publish_count(rig.shm_name()) > published_before + 50);
  const json status = rig.run([&] { return rig.service().status_json(0); });
  CHECK(status["identification"]["state"] == "ok");
  CHECK(status["commands"]["timeouts"] == 0);
}

TEST_CASE("Rescan and acknowledge through EnDatAck wait for the module, then identify again",
          "[endat_e2e][endat_ack]") {
  Rig rig;
  REQUIRE(rig.wait_identified());
  LineClient c(rig.socket_path(), kClientTimeoutMs);
  REQUIRE(c.connected());
  const json rescan = c.request({{"cmd", "endat-rescan"}, {"axis", 0}});
  INFO(rescan.dump());
  REQUIRE(rescan.value("ok", false));
  CHECK(rescan["command"] == "rescan");
  CHECK(rescan["bits"] == 2);
  // The simulated module keeps the bit set while it reads the identification on the wire: the
  // daemon saw it clear, so it read back at least once.
  CHECK(rescan["confirmed"] == true);
  CHECK(rescan["reads"].get<unsigned>() >= 1);
  const json ack = c.request({{"cmd", "endat-ack-register"}, {"axis", 0}});
  INFO(ack.dump());
  REQUIRE(ack.value("ok", false));
  CHECK(ack["bits"] == 1);
  CHECK(ack["confirmed"] == true);
  // ident --refresh: Rescan, then the identification read again.
  const json ident = c.request({{"cmd", "endat-ident"}, {"axis", 0}, {"refresh", true}});
  INFO(ident.dump());
  REQUIRE(ident.value("ok", false));
  CHECK(ident["identification"]["serial"] == "S36845217");
  CHECK(error_code_of(c.request({{"cmd", "endat-rescan"}, {"axis", 3}})) == "bad_argument");
}

TEST_CASE("privileged commands need the privileged group", "[endat_e2e]") {
  Rig rig;
  rig.run([&] {
    rig.service().set_privilege_check([](const control::PeerCredentials&) { return false; });
  });
  LineClient c(rig.socket_path(), kClientTimeoutMs);
  const json w =
      c.request({{"cmd", "endat-write-param"}, {"mrs", 0xA9}, {"param", 1}, {"value", 1}});
  CHECK(error_code_of(w) == "permission_denied");
  CHECK(error_code_of(c.request({{"cmd", "endat-reset"}})) == "permission_denied");
  CHECK(error_code_of(c.request({{"cmd", "endat-ack"}})) == "permission_denied");
  CHECK(error_code_of(c.request({{"cmd", "endat-rescan"}})) == "permission_denied");
  CHECK(error_code_of(c.request({{"cmd", "endat-ack-register"}})) == "permission_denied");
  CHECK(error_code_of(c.request({{"cmd", "endat-write-block"},
                                 {"mrs", 0xB1},
                                 {"block", 0},
                                 {"param", 1},
                                 {"value", 1}})) == "permission_denied");
  // Reads stay open.
  CHECK(c.request({{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", 1}}).value("ok", false));
  CHECK(rig.counters().commands_sent >= 1);
}

TEST_CASE("echo mismatch, truncated reply and timeout are reported, and the next command is right",
          "[endat_e2e]") {
  // Timeouts of 2 s: a good reply must come within it even when the rig's (normal-priority)
  // cycle thread stalls, as under TSan on a loaded machine, where 400 ms was not always enough.
  Rig rig({.peer = Peer::Scripted, .command_timeout_ms = 2000});
  // The identification reads at start first: a read queued behind them would spend part of its
  // timeout waiting.
  REQUIRE(rig.wait_identified());
  LineClient c(rig.socket_path(), kClientTimeoutMs);
  auto read = [&](int param) {
    return c.request({{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", param}});
  };
  const json ok = read(5);
  INFO(ok.dump());
  REQUIRE(ok.value("ok", false));
  CHECK(ok["value"] == (0xA9 << 8 | 5));

  rig.scripted().inject(ScriptedModule::Fault::WrongMrsEcho, 1);
  const json echo = read(6);
  INFO(echo.dump());
  CHECK(error_code_of(echo) == "echo_mismatch");
  CHECK_FALSE(echo.contains("value"));
  CHECK(read(7)["value"] == (0xA9 << 8 | 7));

  rig.scripted().inject(ScriptedModule::Fault::Truncated, 1);
  const json cut = read(8);
  INFO(cut.dump());
  CHECK(error_code_of(cut) == "truncated_reply");
  CHECK(read(9)["value"] == (0xA9 << 8 | 9));

  rig.scripted().inject(ScriptedModule::Fault::Silent, 1);
  const json silent = read(10);
  INFO(silent.dump());
  CHECK(error_code_of(silent) == "timeout");
  CHECK(read(11)["value"] == (0xA9 << 8 | 11));

  // A late reply (after the timeout) is never taken for the next command's: let
  // the reply of a read come 3000 cycles late, then read another parameter at once. 3 s
  // lies midway between the timeout (2 s) and the end of the quiet period after it (4 s), so
  // a cycle thread stalled for up to ~1 s in all changes nothing.
  rig.scripted().inject(ScriptedModule::Fault::Late, 1, 3000);
  const json late = read(12);
  CHECK(error_code_of(late) == "timeout");
  const json after = read(13);
  INFO(after.dump());
  CHECK(after["value"] == (0xA9 << 8 | 13));
  const auto counters = rig.counters();
  CHECK(counters.timeouts == 2);
  CHECK(counters.late_replies == 1);
  CHECK(counters.unexpected_replies == 0);
}

TEST_CASE("a client that disconnects: its queued command is dropped, its reply discarded",
          "[endat_e2e]") {
  Rig rig({.peer = Peer::Scripted, .command_timeout_ms = 10000});
  // A: in flight, answered 2000 cycles late (well within the timeout; the steps below wait
  // for events and take a few cycles). B: queued behind it.
  rig.scripted().inject(ScriptedModule::Fault::Late, 1, 2000);
  {
    LineClient a(rig.socket_path(), kClientTimeoutMs);
    LineClient b(rig.socket_path(), kClientTimeoutMs);
    a.send_raw(json{{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", 40}}.dump() + "\n");
    REQUIRE(ds1928::test::wait_until([&] { return rig.scripted().received_with_param(40) == 1; }));
    b.send_raw(
        json{{"cmd", "endat-write-param"}, {"mrs", 0xA9}, {"param", 41}, {"value", 7}}.dump() +
        "\n");
    REQUIRE(ds1928::test::wait_until([&] {
      return rig.run([&] { return rig.service().status_json(0)["commands"]["queued"] == 1; });
    }));
    b.close();
    REQUIRE(ds1928::test::wait_until([&] { return rig.counters().jobs_cancelled == 1; }));
    a.close();
  }
  LineClient c(rig.socket_path(), kClientTimeoutMs);
  const json r = c.request({{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", 42}});
  INFO(r.dump());
  CHECK(r["value"] == (0xA9 << 8 | 42));
  CHECK(rig.scripted().received_with_param(41) == 0);  // B's write never reached the module
  CHECK(rig.scripted().received_with_param(40) == 1);
  const auto counters = rig.counters();
  CHECK(counters.jobs_cancelled == 2);
  CHECK(counters.discarded_replies == 1);
  CHECK(counters.timeouts == 0);
}

TEST_CASE("under a lossy bus every result is the right value or an explicit error", "[endat_e2e]") {
  const uint32_t seed = static_cast<uint32_t>(std::random_device{}());
  INFO("seed " << seed);
  Rig rig({.peer = Peer::Lossy, .command_timeout_ms = 1000, .seed = seed});
  REQUIRE(rig.wait_identified());
  const uint64_t published_before = publish_count(rig.shm_name());
  const uint64_t cycles_before = rig.cycles();

  // Manufacturer words as the registers show them (identification read at start).
  const json expected_words =
      rig.run([&] { return rig.service().identification_reply(0); })["words"];

  struct Tally {
    int ok = 0, errors = 0, wrong = 0;
    std::map<std::string, int> codes;
    std::vector<std::string> wrong_cases;
  };
  auto client = [&](int first_param, uint32_t client_seed, Tally& t) {
    std::mt19937 rng(client_seed);
    LineClient c(rig.socket_path(), kClientTimeoutMs);
    std::map<int, std::set<int>> possible;  // OEM parameter → values it may hold
    for (int p = first_param; p < first_param + 8; ++p) possible[p] = {0};
    for (int n = 0; n < 160; ++n) {
      const int kind = std::uniform_int_distribution<int>(0, 9)(rng);
      const int p = first_param + std::uniform_int_distribution<int>(0, 7)(rng);
      json req;
      int value = -1;
      if (kind < 4) {
        value = std::uniform_int_distribution<int>(0, 0xFFFF)(rng);
        req = {{"cmd", "endat-write-param"}, {"mrs", 0xA9}, {"param", p}, {"value", value}};
      } else if (kind < 7) {
        req = {{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", p}};
      } else if (kind < 9) {
        req = {{"cmd", "endat-read-param"}, {"mrs", 0xA3}, {"param", p % 16}};
      } else {
        req = {{"cmd", "endat-write-param"}, {"mrs", 0xA5}, {"param", p % 16}, {"value", 0x5A5A}};
      }
      const json r = c.request(req);
      if (!r.is_object()) {
        ++t.wrong;
        t.wrong_cases.push_back("no reply to " + req.dump());
        continue;
      }
      const bool is_ok = r.value("ok", false);
      const std::string code = error_code_of(r);
      if (!is_ok) {
        ++t.errors;
        ++t.codes[code];
        if (code.empty()) {
          ++t.wrong;
          t.wrong_cases.push_back("error without a code: " + r.dump());
        }
      } else {
        ++t.ok;
      }
      auto wrong = [&](const std::string& why) {
        ++t.wrong;
        t.wrong_cases.push_back(why + ": " + req.dump() + " -> " + r.dump());
      };
      if (req["mrs"] == 0xA5) {
        if (is_ok)
          wrong("protected write accepted");
        else if (code != "write_rejected" && code != "timeout" && code != "not_delivered" &&
                 code.rfind("module_", 0) != 0)
          wrong("unexpected error");
      } else if (req["mrs"] == 0xA3) {
        if (is_ok && r["value"] != expected_words[std::to_string(16 + p % 16)]["value"])
          wrong("wrong manufacturer word");
      } else if (value >= 0) {  // OEM write
        if (is_ok) {
          if (r["value"] != value) wrong("write verified with another value");
          possible[p] = {value};
        } else if (code == "write_rejected") {
          wrong("OEM write rejected");
        } else {
          possible[p].insert(value);  // maybe executed
          if (code == "echo_mismatch" || code == "truncated_reply") wrong("malformed reply");
        }
      } else {  // OEM read
        if (is_ok) {
          const int v = r["value"].get<int>();
          if (!possible[p].count(v)) wrong("read a value never written");
          possible[p] = {v};
        }
      }
    }
  };
  Tally a, b;
  std::atomic<bool> finished{false};
  std::thread trace([&] {  // DS1928_E2E_TRACE=1: the service's view every second
    if (!std::getenv("DS1928_E2E_TRACE")) return;
    while (!finished.load()) {
      std::this_thread::sleep_for(std::chrono::seconds(1));
      const auto& tc = rig.work().tunnel_counters(0);
      std::fprintf(
          stderr,
          "%s | fs sent %llu failed %llu received %llu repeated %llu resyncs %llu out %u in %u\n",
          rig.run([&] { return rig.service().status_json(0)["commands"].dump(); }).c_str(),
          (unsigned long long)tc.messages_sent.load(),
          (unsigned long long)tc.messages_failed.load(),
          (unsigned long long)tc.messages_received.load(),
          (unsigned long long)tc.sequences_repeated.load(), (unsigned long long)tc.resyncs.load(),
          tc.output_state.load(), tc.input_state.load());
    }
  });
  std::thread ta([&] { client(0, seed + 1, a); });
  std::thread tb([&] { client(8, seed + 2, b); });
  ta.join();
  tb.join();
  finished.store(true);
  trace.join();

  for (const auto& w : a.wrong_cases) UNSCOPED_INFO(w);
  for (const auto& w : b.wrong_cases) UNSCOPED_INFO(w);
  std::string codes;
  for (const auto* t : {&a, &b})
    for (const auto& [code, n] : t->codes) codes += code + "=" + std::to_string(n) + " ";
  INFO("ok " << a.ok + b.ok << ", errors " << a.errors + b.errors << ": " << codes);
  CHECK(a.wrong + b.wrong == 0);
  CHECK(a.ok + a.errors + b.ok + b.errors == 320);
  // Most commands get through a lossy bus; the protected writes (1 in 10) fail by design.
  CHECK(a.ok + b.ok > 200);
  const auto counters = rig.counters();
  INFO("resends " << counters.resends << ", timeouts " << counters.timeouts << ", late "
                  << counters.late_replies << ", unexpected " << counters.unexpected_replies);
  // The bus did break the tunnel: resynchronisations after the outages.
  CHECK(rig.work().tunnel_counters(0).resyncs.load() > 0);
  // Positions kept flowing: a publication per cycle.
  const uint64_t cycles = rig.cycles() - cycles_before;
  CHECK(publish_count(rig.shm_name()) - published_before + 5 >= cycles);
}

TEST_CASE("an axis queues 16 EnDat commands behind the one in flight, one more is busy",
          "[endat_e2e]") {
  // The first command is never answered (timeout 60 s): it stays in flight, nothing leaves the
  // queue while the test fills it.
  Rig rig({.peer = Peer::Scripted, .command_timeout_ms = 60000});
  rig.scripted().inject(ScriptedModule::Fault::Silent, 1);
  using State = std::pair<bool, std::size_t>;  // in flight, queued
  auto state = [&] {
    return rig.run([&] {
      const json c = rig.service().status_json(0)["commands"];
      return State{c["in_flight"].get<bool>(), c["queued"].get<std::size_t>()};
    });
  };
  std::vector<std::unique_ptr<LineClient>> waiting;
  for (std::size_t i = 0; i <= EnDatService::kQueueDepth; ++i) {
    waiting.push_back(std::make_unique<LineClient>(rig.socket_path(), kClientTimeoutMs));
    REQUIRE(waiting.back()->send_raw(
        json{{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", i}}.dump() + "\n"));
    // The socket is read asynchronously: wait until the service has taken it.
    REQUIRE(ds1928::test::wait_until([&] { return state() == State{true, i}; }));
  }
  LineClient extra(rig.socket_path(), kClientTimeoutMs);
  const json r = extra.request({{"cmd", "endat-read-param"}, {"mrs", 0xA9}, {"param", 99}});
  INFO(r.dump());
  CHECK(error_code_of(r) == "busy");
  CHECK_THAT(control::test::error_message_of(r), Catch::Contains("queue is full"));
  CHECK(state() == State{true, EnDatService::kQueueDepth});
  CHECK(rig.scripted().received_with_param(99) == 0);
}
