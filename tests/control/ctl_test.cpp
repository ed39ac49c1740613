// ds1928ctl against a stand-in daemon in this process: requests and exit codes over the real
// socket, and `position --follow` across a daemon that stops, hangs and restarts.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>

#include "control_test_util.hpp"
#include "shm/publisher.hpp"

using namespace ds1928;
using namespace ds1928::control;
using namespace ds1928::control::test;
using json = nlohmann::json;

namespace {

struct Run {
  int exit = -1;
  std::string out;
};

// Runs ds1928ctl with `args`, stdout captured, stderr discarded.
Run ctl(const std::string& args) {
  Run r;
  FILE* p = popen((std::string(DS1928CTL) + " " + args + " 2>/dev/null").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) r.out.append(buf, n);
  const int status = pclose(p);
  r.exit = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Runs ds1928ctl with `args` under `env` (assignments for env(1), e.g. "DS1928_SOCKET=/x"; the
// variables the tool reads are cleared first), stdout and stderr captured together.
Run ctl_env(const std::string& env, const std::string& args) {
  Run r;
  const std::string cmd = "env -u DS1928_SOCKET -u XDG_RUNTIME_DIR " + env + " " +
                          std::string(DS1928CTL) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) r.out.append(buf, n);
  const int status = pclose(p);
  r.exit = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// A status reply like the daemon's: one axis in `state`, shared memory `shm`.
json status_reply(const std::string& axis_state, const std::string& shm) {
  return {{"daemon",
           {{"version", "0.1.0"},
            {"pid", 1},
            {"state", "running"},
            {"uptime_s", 3.5},
            {"realtime", true},
            {"rt_status", "real-time: SCHED_FIFO 80, CPU 1, memory locked"}}},
          {"shm", {{"name", shm}, {"generation", 7}}},
          {"bus", {{"kind", "simulated"}, {"state", "operational"}}},
          {"cycle", {{"period_us", 1000}, {"count", 3500}, {"overruns", 0}, {"skipped", 0}}},
          {"axes", json::array({{{"axis", 0},
                                 {"name", "x"},
                                 {"state", axis_state},
                                 {"error_info", 0},
                                 {"endat_error", 0},
                                 {"endat_warning", 0}}})}};
}

// Publishes one axis every millisecond on its own thread while alive.
class Publishing {
 public:
  explicit Publishing(shm::Publisher& pub, shm::AxisValidity validity = shm::AxisValidity::Valid)
      : validity(validity), pub_(pub), thread_([this] { loop(); }) {}
  ~Publishing() { stop(); }
  void stop() {
    run_ = false;
    if (thread_.joinable()) thread_.join();
  }

 private:
  void loop() {
    shm::AxisStatus st[1];
    for (uint64_t c = 1; run_; ++c) {
      st[0].sample.position_raw = c << 16;
      st[0].sample.periods = static_cast<int64_t>(c);
      st[0].sample.fresh = true;
      st[0].validity = validity;
      pub_.publish(c, st);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  const shm::AxisValidity validity;
  shm::Publisher& pub_;
  std::atomic<bool> run_{true};
  std::thread thread_;
};

// A ds1928ctl child whose stdout the test reads line by line. Killed and reaped when the test
// ends, also early: a follower waiting for a daemon that never comes back would run forever.
class Child {
 public:
  explicit Child(const std::string& args) {
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], STDOUT_FILENO);
      const int null = ::open("/dev/null", O_WRONLY);
      if (null >= 0) dup2(null, STDERR_FILENO);
      execl("/bin/sh", "sh", "-c", ("exec " + std::string(DS1928CTL) + " " + args).c_str(),
            static_cast<char*>(nullptr));
      _exit(127);
    }
    ::close(fds[1]);
    if (pid_ < 0) {
      ::close(fds[0]);
      return;
    }
    out_ = fdopen(fds[0], "r");
  }
  ~Child() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      wait();
    }
    if (out_ != nullptr) fclose(out_);
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  [[nodiscard]] bool running() const { return pid_ > 0 && out_ != nullptr; }
  // The next line as JSON; null at EOF.
  json next() {
    char line[4096];
    if (out_ == nullptr || fgets(line, sizeof(line), out_) == nullptr) return nullptr;
    return json::parse(line, nullptr, false);
  }
  // Waits for the exit; the wait status.
  int wait() {
    int status = -1;
    if (pid_ > 0) waitpid(pid_, &status, 0);
    pid_ = -1;
    return status;
  }

 private:
  pid_t pid_ = -1;
  FILE* out_ = nullptr;
};

std::string shm_name() {
  return "/ds1928d-ctl-test-" + std::to_string(getpid());
}

}  // namespace

TEST_CASE("ds1928ctl sends requests, prints replies and maps errors to exit codes") {
  SocketConfig cfg;
  cfg.path = temp_socket_path("ctl");
  ServerThread t(cfg);
  json last_ack;
  t.server().add_command("status", [](const Request&, Reply reply) {
    reply.ok({{"daemon",
               {{"version", "0.1.0"},
                {"pid", 1},
                {"state", "running"},
                {"uptime_s", 3.5},
                {"realtime", false},
                {"rt_status", "no privilege"}}},
              {"bus", {{"kind", "simulated"}, {"state", "operational"}}},
              {"cycle", {{"period_us", 1000}, {"count", 3500}, {"overruns", 0}, {"skipped", 0}}},
              {"axes", json::array({{{"axis", 0},
                                     {"name", "x"},
                                     {"state", "valid"},
                                     {"error_info", 0},
                                     {"endat_error", 0},
                                     {"endat_warning", 0}}})}});
  });
  t.server().add_command("ack-errors", [&](const Request& req, Reply reply) {
    const auto axis = req.get_uint("axis", 0);
    const auto bits = req.get_uint("bits", 0xff);
    last_ack = req.body();
    reply.ok({{"axis", axis}, {"bits", bits}});
  });
  REQUIRE_FALSE(t.start());
  const std::string sock = "--socket " + cfg.path;

  Run r = ctl(sock + " status --json");
  CHECK(r.exit == 0);
  const json status = json::parse(r.out, nullptr, false);
  CHECK(status["daemon"]["version"] == "0.1.0");
  CHECK(status["axes"][0]["state"] == "valid");

  r = ctl(sock + " status");
  CHECK(r.exit == 0);
  CHECK_THAT(r.out, Catch::Contains("simulated, operational") && Catch::Contains("3500 cycles"));

  r = ctl(sock + " ack 0 0x30 --json");
  CHECK(r.exit == 0);
  CHECK(t.run([&] { return last_ack; }) ==
        json{{"cmd", "ack-errors"}, {"axis", 0}, {"bits", 0x30}});
  r = ctl(sock + " ack 1 16 --json");  // the daemon has one axis
  CHECK(r.exit == 1);
  const json err = json::parse(r.out, nullptr, false);
  CHECK(err["error"]["code"] == "bad_argument");
  CHECK(ctl(sock + " ack 0 0x100").exit == 2);  // BITS out of range: usage
  CHECK(ctl(sock + " stats").exit == 1);        // unknown_command here
  CHECK(ctl("--socket /nonexistent/ds1928.sock status").exit == 3);
}

TEST_CASE("position --follow says when the daemon stops, hangs or restarts, and resumes") {
  const std::string name = shm_name();
  ShmConfig cfg;
  cfg.name = name;
  auto first = std::make_unique<shm::Publisher>();
  REQUIRE_FALSE(first->open(cfg, 2, 1'000'000));
  auto publishing = std::make_unique<Publishing>(*first);

  // Single read.
  Run once = ctl("--shm " + name + " position --axis 1 --json");
  CHECK(once.exit == 0);
  CHECK(json::parse(once.out, nullptr, false)["axis"] == 1);
  CHECK(ctl("--shm " + name + " position --axis 2").exit == 2);

  Child follower("--shm " + name + " position --axis 0 --follow --json --count 120");
  REQUIRE(follower.running());
  auto next = [&]() -> json { return follower.next(); };
  int positions = 0;
  uint64_t last_cycle = 0;
  bool increasing = true;
  auto expect_positions = [&](int n) {
    for (int i = 0; i < n; ++i) {
      const json j = next();
      REQUIRE(j.is_object());
      REQUIRE(j.contains("cycle"));
      if (j["cycle"].get<uint64_t>() <= last_cycle) increasing = false;
      last_cycle = j["cycle"].get<uint64_t>();
      ++positions;
    }
  };
  expect_positions(40);

  // Clean stop.
  publishing.reset();
  const uint64_t gen1 = first->generation();
  first->close();
  json e = next();
  while (e.is_object() && e.contains("cycle")) {  // publications still in flight
    ++positions;
    e = next();
  }
  CHECK(e["event"] == "stopped");
  CHECK(e["generation"] == gen1);

  // Restart: a new generation, and the follower resumes.
  auto second = std::make_unique<shm::Publisher>();
  REQUIRE_FALSE(second->open(cfg, 2, 1'000'000));
  publishing = std::make_unique<Publishing>(*second);
  e = next();
  CHECK(e["event"] == "restarted");
  CHECK(e["generation"] == second->generation());
  last_cycle = 0;
  expect_positions(40);

  // Hang: publications stop without a goodbye.
  publishing.reset();
  e = next();
  while (e.is_object() && e.contains("cycle")) {
    ++positions;
    e = next();
  }
  CHECK(e["event"] == "not_publishing");
  second->close();
  auto third = std::make_unique<shm::Publisher>();
  REQUIRE_FALSE(third->open(cfg, 2, 1'000'000));
  publishing = std::make_unique<Publishing>(*third);
  e = next();
  CHECK(e["event"] == "restarted");
  last_cycle = 0;
  while (positions < 120) expect_positions(1);
  CHECK(next().is_null());  // --count reached: the follower exits
  // The publishing thread ends before `third`, declared after it, is closed and unmapped.
  publishing.reset();
  const int status = follower.wait();
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
  CHECK(increasing);
}

TEST_CASE("ds1928ctl finds the socket: -s, $DS1928_SOCKET, then the per-user fallback") {
  // The daemon fell back: its socket is in $XDG_RUNTIME_DIR/ds1928d/ under the configured name.
  const std::string xdg = std::filesystem::path(temp_socket_path("xdg")).parent_path().string();
  SocketConfig cfg;
  cfg.path = xdg + "/ds1928d/fallen.sock";
  ServerThread t(cfg);
  t.server().add_command("status", [](const Request&, Reply reply) {
    reply.ok(status_reply("valid", "/ds1928d-none"));
  });
  REQUIRE_FALSE(t.start());
  const std::string env = "XDG_RUNTIME_DIR=" + xdg;

  // The configured path's directory does not exist: the fallback of the same name answers.
  Run r = ctl_env(env, "-s /nonexistent-ds1928/fallen.sock status --json");
  INFO(r.out);
  CHECK(r.exit == 0);
  CHECK(json::parse(r.out, nullptr, false)["daemon"]["version"] == "0.1.0");
  // $DS1928_SOCKET: the same, and -s wins over it.
  CHECK(ctl_env(env + " DS1928_SOCKET=/nonexistent-ds1928/fallen.sock", "status").exit == 0);
  CHECK(ctl_env(env + " DS1928_SOCKET=" + cfg.path, "status").exit == 0);
  r = ctl_env(env + " DS1928_SOCKET=" + cfg.path, "-s /nonexistent-ds1928/other.sock status");
  CHECK(r.exit == 3);
  // Nobody anywhere: the error names every path tried.
  CHECK_THAT(r.out, Catch::Contains("/nonexistent-ds1928/other.sock (No such file") &&
                        Catch::Contains(xdg + "/ds1928d/other.sock (No such file") &&
                        Catch::Contains("is ds1928d running?"));
  // Without XDG_RUNTIME_DIR the fallback is /tmp/ds1928d-<uid>/.
  r = ctl_env("", "-s /nonexistent-ds1928/other.sock status");
  CHECK(r.exit == 3);
  CHECK_THAT(r.out, Catch::Contains("/tmp/ds1928d-" + std::to_string(getuid()) + "/other.sock"));
}

TEST_CASE("-s alone reaches the instance's shared memory, --shm overrides it") {
  const std::string name = shm_name() + "-inst";
  ShmConfig shm_cfg;
  shm_cfg.name = name;
  shm::Publisher pub;
  REQUIRE_FALSE(pub.open(shm_cfg, 1, 1'000'000));
  Publishing publishing(pub);

  SocketConfig cfg;
  cfg.path = temp_socket_path("inst");
  ServerThread t(cfg);
  t.server().add_command(
      "status", [&](const Request&, Reply reply) { reply.ok(status_reply("valid", name)); });
  REQUIRE_FALSE(t.start());

  Run r = ctl_env("", "-s " + cfg.path + " position --axis 0 --json");
  INFO(r.out);
  CHECK(r.exit == 0);
  CHECK(json::parse(r.out, nullptr, false)["axis"] == 0);
  CHECK(ctl_env("DS1928_SOCKET=" + cfg.path, "position --json").exit == 0);
  // --shm still decides.
  r = ctl_env("", "-s " + cfg.path + " --shm " + name + "-absent position");
  CHECK(r.exit == 3);
  CHECK_THAT(r.out, Catch::Contains("no shared memory " + name + "-absent"));
  // A named daemon that cannot be asked: no guess at another instance's memory.
  r = ctl_env("", "-s /nonexistent-ds1928/x.sock position");
  CHECK(r.exit == 3);
  CHECK_THAT(r.out, Catch::Contains("give --shm NAME"));
  publishing.stop();
}

TEST_CASE("status --check and position --check exit 5 while an axis is not valid") {
  const std::string name = shm_name() + "-check";
  ShmConfig shm_cfg;
  shm_cfg.name = name;
  shm::Publisher pub;
  REQUIRE_FALSE(pub.open(shm_cfg, 1, 1'000'000));
  auto publishing = std::make_unique<Publishing>(pub, shm::AxisValidity::BusDown);

  std::string state = "bus_down";
  SocketConfig cfg;
  cfg.path = temp_socket_path("check");
  ServerThread t(cfg);
  t.server().add_command("status",
                         [&](const Request&, Reply reply) { reply.ok(status_reply(state, name)); });
  REQUIRE_FALSE(t.start());
  const std::string sock = "-s " + cfg.path + " ";

  Run r = ctl_env("", sock + "status --check");
  INFO(r.out);
  CHECK(r.exit == 5);
  CHECK_THAT(r.out, Catch::Contains("not valid: axis 0 (x): bus_down"));
  CHECK(ctl_env("", sock + "status").exit == 0);  // without --check: the daemon answered
  CHECK(ctl_env("", sock + "--json status --check").exit == 5);
  r = ctl_env("", sock + "position --check");
  CHECK(r.exit == 5);
  CHECK_THAT(r.out, Catch::Contains("not valid: axis 0: bus_down"));
  CHECK(ctl_env("", sock + "position").exit == 0);

  for (const char* bad : {"module_error", "stale"}) {
    t.run([&] { state = bad; });
    CHECK(ctl_env("", sock + "status --check").exit == 5);
  }
  t.run([&] { state = "valid"; });
  publishing = std::make_unique<Publishing>(pub, shm::AxisValidity::Valid);
  CHECK(ctl_env("", sock + "status --check").exit == 0);
  CHECK(ctl_env("", sock + "position --check").exit == 0);
  CHECK(ctl_env("", sock + "position --check --follow").exit == 2);  // a verdict ends; --follow not
  publishing.reset();
}

// Without an incident directory no file is written: the tool prints the daemon's note, not a
// promise of a file in "-".
TEST_CASE("incident mark prints the daemon's note on where the file goes") {
  SocketConfig cfg;
  cfg.path = temp_socket_path("mark");
  ServerThread t(cfg);
  json marked{
      {"number", 3},
      {"joined", false},
      {"file_after_ms", 2000},
      {"dir", nullptr},
      {"file_written", false},
      {"note", "no incident directory (flight_recorder.dir is empty ...): no file is written"}};
  t.server().add_command("incident-mark", [&](const Request&, Reply r) {
    r.ok({{"marked", marked}});
  });
  REQUIRE_FALSE(t.start());
  Run r = ctl_env("", "-s " + cfg.path + " incident mark 'by the test'");
  INFO(r.out);
  CHECK(r.exit == 0);
  CHECK_THAT(r.out, Catch::Contains("incident 3 marked; no incident directory"));
  CHECK_THAT(r.out, !Catch::Contains("follows in"));
}

TEST_CASE("status prints each bus's own node fields and the bus state's cause") {
  json reply = status_reply("bus_down", "/ds1928d-none");
  reply["axes"][0]["module_state"] = "preop";
  reply["axes"][0]["module_error_class"] = "system";
  reply["axes"][0]["module"] = {{"r_led", "blinking"}, {"e_led", "double_flash"}};
  reply["bus"] = {
      {"kind", "canio"},
      {"state", "no_nodes"},
      {"cause",
       "register 1025 (SinCosEnable) = 1: no SDO response (node silent or not a CANopen SDO "
       "server)"},
      {"interface", "vcan7"},
      {"transport", "virtual"},
      {"can_state", "error-active"},
      {"bitrate", 500000},
      {"canopen_nodes", json::array({{{"node", 1},
                                      {"nmt_state", "operational"},
                                      {"boot_ups", 1},
                                      {"heartbeat_watched", true},
                                      {"heartbeats", 120},
                                      {"heartbeat_misses", 2},
                                      {"emcys", 0}}})},
      {"nodes", json::array({{{"axis", 0},
                              {"node", 1},
                              {"state", "configured"},
                              {"reason", ""},
                              {"samples", 1234},
                              {"missing", 5},
                              {"late_frames", 6},
                              {"last_error", "SDO abort 0x06020000"}}})}};
  SocketConfig cfg;
  cfg.path = temp_socket_path("canio");
  ServerThread t(cfg);
  t.server().add_command("status", [&](const Request&, Reply r) { r.ok(reply); });
  REQUIRE_FALSE(t.start());

  Run r = ctl_env("", "-s " + cfg.path + " status");
  INFO(r.out);
  CHECK(r.exit == 0);
  CHECK_THAT(r.out, Catch::Contains("bus:       canio, no_nodes\n    cause: register 1025"));
  CHECK_THAT(r.out, Catch::Contains("interface vcan7 (virtual), error-active, 500000 bit/s"));
  CHECK_THAT(r.out, Catch::Contains("node 1: NMT operational, heartbeats 120 (2 missed), "
                                    "boot-ups 1, EMCY 0"));
  CHECK_THAT(r.out, Catch::Contains("axis 0: configured, samples 1234, missing 5, late 6"));
  CHECK_THAT(r.out, Catch::Contains("last error: SDO abort 0x06020000"));
  // The module's state like its r-LED, the e-LED's class when one is lit.
  CHECK_THAT(r.out, Catch::Contains("x            bus_down      module preop  ErrorInfo"));
  CHECK_THAT(r.out, Catch::Contains("module e-LED double_flash: system"));
  CHECK_THAT(r.out, !Catch::Contains("PRes") && !Catch::Contains("NMT ?"));
  // The engine's text is not repeated after yes/no.
  CHECK_THAT(r.out, Catch::Contains("real-time: yes (SCHED_FIFO 80, CPU 1, memory locked)"));

  // POWERLINK nodes keep their fields; no cause line while the bus is operational.
  t.run([&] {
    reply["bus"] = {{"kind", "powerlink"},
                    {"state", "operational"},
                    {"mn_state", "operational"},
                    {"nodes", json::array({{{"node", 1},
                                            {"boot", "operational"},
                                            {"nmt", "operational"},
                                            {"boots", 1},
                                            {"resets", 0},
                                            {"loss_of_pres", {{"events", 3}}}}})}};
  });
  r = ctl_env("", "-s " + cfg.path + " status");
  CHECK_THAT(r.out, Catch::Contains("node 1: operational (NMT operational), boots 1, resets 0, "
                                    "PRes losses 3"));
  CHECK_THAT(r.out, !Catch::Contains("cause:"));
}

TEST_CASE("capture refused by the daemon leaves no output file") {
  SocketConfig cfg;
  cfg.path = temp_socket_path("capture");
  ServerThread t(cfg);
  t.server().add_command("capture", [](const Request&, Reply reply) {
    reply.error("no_capture_point", "this bus has no capture point");
  });
  REQUIRE_FALSE(t.start());
  const auto file = std::filesystem::path(cfg.path).parent_path() / "out.pcapng";
  Run r = ctl_env("", "-s " + cfg.path + " capture -w " + file.string() + " --count 1");
  INFO(r.out);
  CHECK(r.exit == 1);
  CHECK_THAT(r.out, Catch::Contains("no_capture_point"));
  CHECK_FALSE(std::filesystem::exists(file));
  // An unwritable place is a usage error before anything is asked.
  r = ctl_env("", "-s " + cfg.path + " capture -w /nonexistent-ds1928/out.pcapng --count 1");
  CHECK(r.exit == 2);
  CHECK_THAT(r.out, Catch::Contains("cannot write /nonexistent-ds1928/out.pcapng"));
}

TEST_CASE("ds1928ctl's words: did you mean, --version, doctor's default configuration") {
  Run r = ctl_env("", "stauts");
  INFO(r.out);
  CHECK(r.exit == 2);
  CHECK_THAT(r.out, Catch::Contains("unknown command 'stauts'; did you mean 'status'?"));
  r = ctl_env("", "-s /x.sock --timeout 5 postion --axis 0");
  CHECK(r.exit == 2);
  CHECK_THAT(r.out, Catch::Contains("did you mean 'position'?"));
  r = ctl_env("", "endat --axis 0 idnet");
  CHECK(r.exit == 2);
  CHECK_THAT(r.out, Catch::Contains("unknown command 'idnet' of 'endat'; did you mean 'ident'?"));
  r = ctl_env("", "frobnicate");
  CHECK(r.exit == 2);
  CHECK_THAT(r.out, Catch::Contains("unknown command 'frobnicate'; commands: status, axes"));
  r = ctl_env("", "--version");
  CHECK(r.exit == 0);
  CHECK_THAT(r.out, Catch::StartsWith("ds1928ctl " PROJECT_VERSION));
  r = ctl_env("", "doctor --help");
  CHECK(r.exit == 0);
  CHECK_THAT(r.out, Catch::Contains("/etc/ds1928d/ds1928d.yaml"));
}
