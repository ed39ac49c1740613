// The running daemon (simulated bus) behind its real control socket: every command, bad input
// of every kind, and 100 concurrent clients — while the cycle keeps its timeline.
#include <grp.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "../control/control_test_util.hpp"
#include "daemon.hpp"
#include "support/unix_socket.hpp"
#include "support/wait.hpp"

using namespace ds1928;
using json = nlohmann::json;

namespace {

// The control tests' line client, with replies that never throw: a failure shows up as an empty
// object in the caller's checks, never as an exception in a client thread that would abort the
// test without cleaning up.
class Client {
 public:
  explicit Client(const std::string& path, int timeout_ms = 5000) : line_(path, timeout_ms) {}
  [[nodiscard]] bool connected() const { return line_.connected(); }
  void send_raw(const std::string& bytes) { (void)line_.send_raw(bytes); }
  // One reply line, or "" when the daemon closed the connection / timed out.
  std::string read_line() { return line_.read_line().value_or(std::string()); }
  json request(const json& j) {
    const json r = line_.request(j);
    return r.is_object() ? r : json::object();
  }

 private:
  control::test::LineClient line_;
};

struct RunningDaemon {
  explicit RunningDaemon(const std::string& tag) {
    dir = std::filesystem::temp_directory_path() /
          ("ds1928d-test-" + tag + "-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    remove_dir.path = dir;
    // Not under systemd: no StateDirectory for the flight recorder's files.
    unsetenv("STATE_DIRECTORY");
    DaemonConfig c;
    c.cycle.period_us = 1000;
    c.cycle.hold_cpu_dma_latency = false;
    c.axes.resize(2);
    c.axes[0].name = "x";
    c.axes[1].name = "y";
    c.axes[1].slot = 2;
    c.shm.name = "/ds1928d-sock-" + tag + "-" + std::to_string(::getpid());
    c.socket.path = (dir / "control.sock").string();
    c.socket.max_clients = 128;
    c.socket.max_request_bytes = 1024;
    // The test is its own privileged client (ack-errors), also when not run as root.
    if (const group* g = getgrgid(getegid())) c.socket.privileged_group = g->gr_name;
    daemon = std::make_unique<Daemon>(c);
    thread = std::thread([this] { rc = daemon->run(); });
    (void)test::wait_until([&] { return test::unix_socket_accepts(c.socket.path); });
    path = c.socket.path;
  }
  ~RunningDaemon() {
    daemon->request_stop();
    thread.join();
  }
  // Removed last, also when the daemon's constructor throws.
  struct RemoveDir {
    std::filesystem::path path;
    ~RemoveDir() {
      std::error_code ec;
      if (!path.empty()) std::filesystem::remove_all(path, ec);
    }
  } remove_dir;
  std::filesystem::path dir;
  std::string path;
  std::unique_ptr<Daemon> daemon;
  std::thread thread;
  int rc = -1;
};

json stats(const std::string& path) {
  return Client(path).request({{"cmd", "stats"}});
}

// Asks `request` until `pred` holds for the reply (the daemon comes up and applies requests
// asynchronously); returns the last reply. The deadline only bounds a failing test.
template <class Pred>
json request_until(Client& c, const json& request, Pred pred) {
  json r;
  (void)test::wait_until([&] {
    r = c.request(request);
    return pred(r);
  });
  return r;
}

}  // namespace

TEST_CASE("every command answers with its documented fields", "[daemon][socket]") {
  RunningDaemon d("cmds");
  Client c(d.path);
  REQUIRE(c.connected());
  const json status = request_until(c, {{"cmd", "status"}, {"id", 7}}, [](const json& r) {
    return r.is_object() && r.value("ok", false) && r["cycle"]["count"].get<uint64_t>() > 50 &&
           r["axes"].size() == 2 && r["axes"][0]["state"] == "valid";
  });
  REQUIRE(status.value("ok", false));
  CHECK(status["id"] == 7);
  CHECK(status["daemon"]["state"] == "running");
  CHECK(status["bus"]["kind"] == "simulated");
  CHECK(status["bus"]["state"] == "operational");
  CHECK(status["cycle"]["count"].get<uint64_t>() > 50);
  REQUIRE(status["axes"].size() == 2);
  CHECK(status["axes"][1]["name"] == "y");
  CHECK(status["axes"][0]["state"] == "valid");

  const json axes = c.request({{"cmd", "axes"}});
  REQUIRE(axes.value("ok", false));
  CHECK(axes["axes"][0]["position_raw"].get<uint64_t>() > 0);
  CHECK((axes["axes"][0]["position_raw"].get<uint64_t>() & 7) == 0);
  CHECK(axes["axes"][1]["slot"] == 2);

  const json st = c.request({{"cmd", "stats"}});
  REQUIRE(st.value("ok", false));
  CHECK(st["cycle"]["wake_latency_ns"]["count"].get<uint64_t>() > 0);

  const json reset = c.request({{"cmd", "stats-reset"}});
  CHECK(reset.value("ok", false));
  // The cycle thread applies the reset at its next cycle.
  const json after_reset = request_until(c, {{"cmd", "stats"}}, [](const json& r) {
    return r.is_object() && r.value("ok", false) &&
           r["cycle"]["reset_generation"].get<uint64_t>() >= 1;
  });
  CHECK(after_reset["cycle"]["reset_generation"].get<uint64_t>() >= 1);

  const json ack = c.request({{"cmd", "ack-errors"}, {"axis", 1}, {"bits", 0x10}});
  CHECK(ack.value("ok", false));
  CHECK(ack["bits"] == 0x10);
  const json bad_axis = c.request({{"cmd", "ack-errors"}, {"axis", 9}, {"bits", 1}});
  CHECK_FALSE(bad_axis.value("ok", true));
  CHECK(bad_axis["error"]["code"] == "bad_argument");
  CHECK(bad_axis["error"]["message"].get<std::string>().find("axis") != std::string::npos);

  // POWERLINK raw process data exists only on the powerlink bus: a named refusal here.
  const json pres = c.request({{"cmd", "pl-pres"}, {"node", 1}});
  CHECK(pres["error"]["code"] == "not_powerlink");
  const json preq = c.request({{"cmd", "pl-preq-set"}, {"node", 1}, {"offset", 0}, {"hex", "0a"}});
  CHECK_FALSE(preq.value("ok", true));
  // The EnDat service answers through the same socket.
  const json ident = c.request({{"cmd", "endat-ident"}, {"axis", 0}});
  CHECK(ident.value("ok", false));
  // The simulated bus has no wire: nothing to capture, said so; status shows no capture.
  CHECK(status["capture"]["running"] == false);
  CHECK(status["capture"]["interfaces"].empty());
  const json cap = c.request({{"cmd", "capture"}, {"duration_ms", 100}});
  CHECK(cap["error"]["code"] == "no_capture_point");
  CHECK(c.request({{"cmd", "capture"}, {"format", "tcpdump"}})["error"]["code"] == "bad_argument");
  CHECK(c.request({{"cmd", "capture-stop"}})["error"]["code"] == "no_capture");
  // The flight recorder without a directory (no flight_recorder.dir, not under systemd): the mark
  // is listed, and the reply says that no file follows instead of naming an empty directory.
  const json mark = c.request({{"cmd", "incident-mark"}, {"text", "by the test"}});
  REQUIRE(mark.value("ok", false));
  CHECK(mark["marked"]["dir"].is_null());
  CHECK(mark["marked"]["file_written"] == false);
  CHECK(mark["marked"]["note"].get<std::string>().find("no incident directory") !=
        std::string::npos);
}

TEST_CASE("bad requests get precise errors and the connection survives", "[daemon][socket]") {
  RunningDaemon d("bad");
  Client c(d.path);
  REQUIRE(c.connected());
  c.send_raw("{not json\n");
  CHECK(json::parse(c.read_line())["error"]["code"] == "bad_json");
  CHECK(c.request({{"cmd", "launch-rockets"}})["error"]["code"] == "unknown_command");
  CHECK(c.request({{"cmd", "ack-errors"}, {"axis", "zero"}, {"bits", 1}})["error"]["code"] ==
        "bad_argument");
  CHECK(c.request({{"cmd", "ack-errors"}, {"axis", 0}, {"bits", 300}})["error"]["code"] ==
        "bad_argument");
  CHECK(c.request({{"cmd", "ack-errors"}, {"axis", 0}})["error"]["code"] == "bad_argument");
  CHECK(c.request(json::array({1, 2}))["error"]["code"] == "bad_json");
  // Still usable after all of that.
  CHECK(c.request({{"cmd", "status"}}).value("ok", false));

  Client big(d.path);
  big.send_raw(std::string(5000, 'x') + "\n");
  const auto line = big.read_line();
  REQUIRE_FALSE(line.empty());
  CHECK(json::parse(line)["error"]["code"] == "request_too_large");
}

TEST_CASE("100 concurrent clients and abrupt disconnects leave the cycle untouched",
          "[daemon][socket]") {
  RunningDaemon d("flood");
  // Past the start-up (first page faults, thread creation) before any window is measured.
  Client warm(d.path);
  REQUIRE(request_until(warm, {{"cmd", "stats"}}, [](const json& r) {
            return r.value("ok", false) && r["cycle"]["count"].get<uint64_t>() >= 300;
          }).value("ok", false));
  // Overruns also come from the machine (a stalled VM, other processes' real-time threads):
  // each attempt compares the flood with a quiet window just before it, and a random stall
  // in the flood window gets another attempt. A cycle the clients really disturb overruns in
  // every attempt.
  constexpr int kAttempts = 3;
  bool untouched = false;
  for (int attempt = 1; attempt <= kAttempts && !untouched; ++attempt) {
    // A quiet window first, as the reference for this machine right now.
    // A window of 1000 cycles, counted by the daemon, not by this thread's clock.
    const json q0 = stats(d.path);
    REQUIRE(q0.value("ok", false));
    const uint64_t q0_count = q0["cycle"]["count"].get<uint64_t>();
    Client quiet_client(d.path);
    const json q1 = request_until(quiet_client, {{"cmd", "stats"}}, [&](const json& r) {
      return r.value("ok", false) && r["cycle"]["count"].get<uint64_t>() >= q0_count + 1000;
    });
    REQUIRE(q1.value("ok", false));

    std::vector<std::thread> clients;
    std::atomic<int> ok{0}, answered_errors{0};
    for (int i = 0; i < 100; ++i) {
      clients.emplace_back([&, i] {
        // Every request is answered; how soon depends on the machine (100 threads against the
        // daemon's one, 10x slower under TSan): a generous timeout keeps the count exact.
        Client c(d.path, 60000);
        if (!c.connected()) return;
        for (int k = 0; k < 20; ++k) {
          switch ((i + k) % 4) {
            case 0:
              ok += c.request({{"cmd", "status"}}).value("ok", false);
              break;
            case 1:
              ok += c.request({{"cmd", "axes"}}).value("ok", false);
              break;
            case 2:
              answered_errors += !c.request({{"cmd", "nope"}}).value("ok", true);
              break;
            case 3:
              // Half a request, then gone.
              if (k == 19) {
                c.send_raw("{\"cmd\":\"sta");
                return;
              }
              ok += c.request({{"cmd", "stats"}}).value("ok", false);
              break;
          }
        }
      });
    }
    for (auto& t : clients) t.join();
    const json f1 = stats(d.path);
    REQUIRE(f1.value("ok", false));

    const auto overruns = [](const json& a, const json& b) {
      return b["cycle"]["overruns"].get<uint64_t>() - a["cycle"]["overruns"].get<uint64_t>();
    };
    const uint64_t quiet = overruns(q0, q1);
    const uint64_t flood = overruns(q1, f1);
    INFO("attempt " << attempt << ": overruns: quiet window " << quiet << ", flood " << flood
                    << "; p99 wake-up " << f1["cycle"]["wake_latency_ns"]["p99"] << " ns");
    CHECK(ok.load() >= 1400);
    CHECK(answered_errors.load() >= 400);
    // The cycle kept running at its rate during the flood.
    CHECK(f1["cycle"]["count"].get<uint64_t>() > q1["cycle"]["count"].get<uint64_t>());
    untouched = flood <= quiet + 2;
    if (attempt == kAttempts) CHECK(untouched);
  }
  CHECK(untouched);
  CHECK(Client(d.path).request({{"cmd", "status"}}).value("ok", false));
}
