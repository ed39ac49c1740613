// ds1928ctl against a stand-in daemon in this process: requests and exit codes over the real
// socket, and `position --follow` across a daemon that stops, hangs and restarts.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <cstdio>
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

// Publishes one axis every millisecond on its own thread while alive.
class Publishing {
 public:
  explicit Publishing(shm::Publisher& pub) : pub_(pub), thread_([this] { loop(); }) {}
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
      st[0].validity = shm::AxisValidity::Valid;
      pub_.publish(c, st);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
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
