#include "core/cycle_engine.hpp"

#include <grp.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>

#include "core/rt_setup.hpp"
#include "support/wait.hpp"

using namespace ds1928;

namespace {

CycleConfig test_config(uint32_t period_us) {
  CycleConfig c;
  c.period_us = period_us;
  c.rt_priority = 80;
  c.cpu = -1;
  c.spin_us = 0;
  c.hold_cpu_dma_latency = true;
  c.lock_memory = true;
  return c;
}

void busy_wait_ns(int64_t ns) {
  const int64_t until = rt::now_ns() + ns;
  while (rt::now_ns() < until) {
  }
}

// Records what each cycle saw, into storage sized up front.
struct RecordingTask : CycleTask {
  struct Entry {
    CycleContext ctx;
    int64_t entered_ns;  // the task's own clock read, independent of the engine's
    int policy;
  };
  explicit RecordingTask(std::size_t capacity) { entries.resize(capacity); }
  void run_cycle(const CycleContext& ctx) noexcept override {
    const int64_t entered = rt::now_ns();
    int policy = -1;
    sched_param param{};
    pthread_getschedparam(pthread_self(), &policy, &param);
    if (count < entries.size()) entries[count] = Entry{ctx, entered, policy};
    ++count;
    if (work_ns > 0) busy_wait_ns(work_ns);
    if (ctx.index == sleep_at_index && sleep_ns > 0) {
      const timespec ts{0, static_cast<long>(sleep_ns)};
      nanosleep(&ts, nullptr);
      slept_until_ns = rt::now_ns();
    }
  }
  std::vector<Entry> entries;
  std::size_t count = 0;
  int64_t work_ns = 0;
  uint64_t sleep_at_index = ~uint64_t{0};
  int64_t sleep_ns = 0;
  int64_t slept_until_ns = 0;
};

}  // namespace

TEST_CASE("cycle configuration is validated", "[cycle_engine]") {
  auto c = test_config(1000);
  CHECK_FALSE(CycleEngine::validate(c));
  c.period_us = 0;
  CHECK(CycleEngine::validate(c) == CycleErrc::InvalidPeriod);
  c = test_config(1000);
  c.rt_priority = 0;
  CHECK(CycleEngine::validate(c) == CycleErrc::InvalidPriority);
  c.rt_priority = 100;
  CHECK(CycleEngine::validate(c) == CycleErrc::InvalidPriority);
  c = test_config(1000);
  c.cpu = 4000;
  CHECK(CycleEngine::validate(c) == CycleErrc::InvalidCpu);
  c = test_config(1000);
  c.spin_us = 1000;
  CHECK(CycleEngine::validate(c) == CycleErrc::InvalidSpin);
  CHECK(make_error_code(CycleErrc::InvalidSpin).message().find("spin_us") != std::string::npos);
  CHECK(std::string(cycle_category().name()) == "ds1928.cycle");

  RecordingTask task(1);
  c = test_config(1000);
  c.period_us = 0;
  auto engine = std::make_unique<CycleEngine>(c, task);
  auto r = engine->start();
  CHECK(r.error == CycleErrc::InvalidPeriod);
  CHECK_FALSE(engine->running());
  CHECK(task.count == 0);
}

TEST_CASE("cycle timeline is absolute: work does not shift later cycles", "[cycle_engine]") {
  constexpr std::size_t kCycles = 400;
  constexpr int64_t kPeriod = 1'000'000;
  RecordingTask task(kCycles);
  task.work_ns = 300'000;  // a relative sleep would drift by this much every cycle
  auto engine = std::make_unique<CycleEngine>(test_config(1000), task);
  auto r = engine->run_cycles(kCycles);
  REQUIRE_FALSE(r.error);
  REQUIRE(task.count == kCycles);
  CHECK(engine->cycle_count() == kCycles);

  const auto& e = task.entries;
  const int64_t t0 = e[0].ctx.start_ns - static_cast<int64_t>(e[0].ctx.index) * kPeriod;
  std::vector<int64_t> lateness;
  for (const auto& x : e) {
    // Every nominal start sits exactly on the grid, and nobody starts before it.
    REQUIRE(x.ctx.start_ns == t0 + static_cast<int64_t>(x.ctx.index) * kPeriod);
    REQUIRE(x.ctx.woke_ns >= x.ctx.start_ns);
    REQUIRE(x.entered_ns >= x.ctx.woke_ns);
    lateness.push_back(x.entered_ns - x.ctx.start_ns);
  }
  // Against the task's own clock, cycle i runs (index_i − index_0) periods after cycle 0, give
  // or take its wake-up latency — it does not drift by the 300 µs of work per cycle (which
  // would be 90 ms between the first and the last quarter). Medians of each quarter compared
  // with each other ignore late wake-ups, also of cycle 0, on a loaded machine.
  auto median_offset = [&](std::size_t from, std::size_t to) {
    std::vector<int64_t> offsets;
    for (std::size_t i = from; i < to; ++i) {
      const int64_t nominal = static_cast<int64_t>(e[i].ctx.index - e[0].ctx.index) * kPeriod;
      offsets.push_back(e[i].entered_ns - e[0].entered_ns - nominal);
    }
    std::nth_element(offsets.begin(), offsets.begin() + offsets.size() / 2, offsets.end());
    return offsets[offsets.size() / 2];
  };
  const int64_t first_quarter = median_offset(0, kCycles / 4);
  const int64_t last_quarter = median_offset(kCycles * 3 / 4, kCycles);
  const int64_t drift = last_quarter - first_quarter;
  INFO("median offset: first quarter " << first_quarter << " ns, last quarter " << last_quarter
                                       << " ns");
  CHECK(std::llabs(drift) < 1'000'000);
  // Most cycles start within their own period (a relative timeline would fall further behind
  // with every cycle).
  std::nth_element(lateness.begin(), lateness.begin() + kCycles / 2, lateness.end());
  CHECK(lateness[kCycles / 2] < kPeriod);

  const auto s = engine->stats_snapshot();
  CHECK(s.cycles == kCycles);
  CHECK(s.wake_latency.count == kCycles);
  CHECK(s.work.p50_ns >= 300'000);  // the busy wait is what the work histogram measures
  CHECK(s.work.p50_ns < 1'000'000);
  // With no overrun the grid is contiguous; with one (a heavily loaded machine) the gaps are
  // exactly the skipped cycles.
  CHECK(e.back().ctx.index - e.front().ctx.index + 1 == kCycles + s.skipped_cycles);
}

TEST_CASE("a long cycle 0 (start-up work) is no overrun: the grid starts one period after it",
          "[cycle_engine]") {
  constexpr std::size_t kCycles = 6;
  constexpr int64_t kPeriod = 1'000'000;
  RecordingTask task(kCycles);
  task.sleep_at_index = 0;
  task.sleep_ns = 3'500'000;  // what a start's first cycle took (3.4 ms at 1 ms)
  auto engine = std::make_unique<CycleEngine>(test_config(1000), task);
  REQUIRE_FALSE(engine->run_cycles(kCycles).error);
  REQUIRE(task.count == kCycles);
  const auto& e = task.entries;
  // Reported on its own, whole.
  CHECK(engine->first_cycle_work_ns() >= 3'500'000);
  // The slot after cycle 0 is cycle 1, not the first slot of the old grid still ahead (4).
  CHECK(e[0].ctx.index == 0);
  CHECK(e[1].ctx.index == 1);
  CHECK(e[1].ctx.start_ns >= task.slept_until_ns);
  CHECK(e[1].ctx.start_ns - e[0].ctx.start_ns >= 3'500'000 + kPeriod);
  // Overruns and skipped slots are only those of later cycles (none on a quiet machine): the
  // gaps after cycle 1 are exactly the skipped slots counted.
  uint64_t gaps = 0;
  for (std::size_t i = 2; i < kCycles; ++i) gaps += e[i].ctx.index - e[i - 1].ctx.index - 1;
  const auto s = engine->stats_snapshot();
  CHECK(s.skipped_cycles == gaps);
  CHECK(s.cycles == kCycles);
}

TEST_CASE("overrun is counted and the timeline skips forward on the grid", "[cycle_engine]") {
  constexpr std::size_t kCycles = 20;
  constexpr int64_t kPeriod = 1'000'000;
  // Which slot follows the long cycle depends on when the engine reads the clock after it: a
  // stall right there (a loaded machine) legitimately loses one more slot, which looks like
  // skipping too far. So that one bound is retried on a fresh engine; a systematic error
  // fails every attempt. Everything else is checked at every attempt.
  constexpr int kAttempts = 5;
  bool first_future_slot = false;
  for (int attempt = 1; attempt <= kAttempts && !first_future_slot; ++attempt) {
    RecordingTask task(kCycles);
    task.sleep_at_index = 5;
    task.sleep_ns = 2'500'000;  // cycle 5 ends around t0 + 7.5 periods: slots 6 and 7 are lost
    auto engine = std::make_unique<CycleEngine>(test_config(1000), task);
    REQUIRE_FALSE(engine->run_cycles(kCycles).error);
    REQUIRE(task.count == kCycles);

    const auto& e = task.entries;
    // The grid is that of cycle 1 on: a cycle 0 stretched by the machine moves it (start-up).
    const int64_t t0 = e[1].ctx.start_ns - static_cast<int64_t>(e[1].ctx.index) * kPeriod;
    uint64_t gaps = 0;
    uint64_t overrun_cycles = 0;
    std::size_t pos5 = kCycles;
    for (std::size_t i = 1; i < kCycles; ++i) {
      REQUIRE(e[i].ctx.start_ns == t0 + static_cast<int64_t>(e[i].ctx.index) * kPeriod);
      if (e[i].ctx.index == 5) pos5 = i;
      if (i > 0 && e[i].ctx.index != e[i - 1].ctx.index + 1) {
        REQUIRE(e[i].ctx.index > e[i - 1].ctx.index);
        gaps += e[i].ctx.index - e[i - 1].ctx.index - 1;
        ++overrun_cycles;
      }
    }
    // A machine stall before cycle 5 can overrun an earlier cycle and skip slot 5 itself: the
    // long cycle never ran, so this attempt proves nothing. Try again (every attempt failing
    // still fails the test below).
    if (pos5 + 1 >= kCycles) continue;
    // The cycle after the long one is the first grid slot still in the future when the long
    // one ended: 8 normally (9 or later only if cycle 5 itself woke or slept late).
    const uint64_t after = e[pos5 + 1].ctx.index;
    const int64_t ended = task.slept_until_ns;
    INFO("attempt " << attempt << ": cycle after 5: " << after << ", cycle 5 ended " << ended - t0
                    << " ns after t0");
    CHECK(after >= 8);
    CHECK(t0 + static_cast<int64_t>(after) * kPeriod > ended);
    CHECK(e[pos5 + 1].ctx.woke_ns >= t0 + static_cast<int64_t>(after) * kPeriod);
    // 200 µs allows for the engine's clock read coming a moment after the task's.
    first_future_slot = t0 + static_cast<int64_t>(after - 1) * kPeriod <= ended + 200'000;
    if (attempt == kAttempts) CHECK(first_future_slot);

    const auto s = engine->stats_snapshot();
    CHECK(s.overruns >= 1);
    CHECK(s.overruns == overrun_cycles);
    CHECK(s.skipped_cycles == gaps);
    CHECK(s.skipped_cycles >= 2);
    CHECK(s.cycles == kCycles);
    CHECK(s.work.max_ns >= 2'500'000);
  }
  CHECK(first_future_slot);
}

TEST_CASE("stats reset requested from another thread is applied by the cycle thread",
          "[cycle_engine]") {
  RecordingTask task(0);
  auto engine = std::make_unique<CycleEngine>(test_config(500), task);
  REQUIRE_FALSE(engine->start().error);
  auto wait_for = [](auto&& pred) { return ds1928::test::wait_until(pred); };
  REQUIRE(wait_for([&] { return engine->cycle_count() >= 200; }));
  auto before = engine->stats_snapshot();
  CHECK(before.cycles >= 200);
  CHECK(before.reset_generation == 0);

  const uint64_t count_at_request = engine->cycle_count();
  engine->request_stats_reset();
  REQUIRE(wait_for([&] { return engine->stats_snapshot().reset_generation == 1; }));
  const auto after = engine->stats_snapshot();
  const uint64_t count_at_reset = engine->cycle_count();
  // Restarted from zero after the request: it cannot hold more cycles than ran since then.
  // (A reset that did not happen would hold every cycle since the start: more than that.)
  CHECK(after.cycles <= count_at_reset - count_at_request);
  CHECK(after.wake_latency.count == after.cycles);

  REQUIRE(wait_for([&] { return engine->cycle_count() >= count_at_reset + 100; }));
  engine->stop();
  CHECK_FALSE(engine->running());
  const auto end = engine->stats_snapshot();
  CHECK(end.cycles >= 100);
  CHECK(end.cycles < engine->cycle_count());  // cycle_count() is never reset
  CHECK(end.wake_latency.count == end.cycles);
  // Stopped: stop() returned after joining the cycle thread, so no cycle can follow.
  const uint64_t stopped_at = engine->cycle_count();
  std::this_thread::yield();
  CHECK(engine->cycle_count() == stopped_at);
}

TEST_CASE("engine refuses a second start while running and restarts after stop", "[cycle_engine]") {
  RecordingTask task(0);
  auto engine = std::make_unique<CycleEngine>(test_config(1000), task);
  REQUIRE_FALSE(engine->start().error);
  CHECK(engine->running());
  CHECK(engine->start().error == CycleErrc::AlreadyRunning);
  engine->stop();
  engine->stop();  // idempotent
  CHECK_FALSE(engine->running());
  const auto n = engine->cycle_count();
  REQUIRE_FALSE(engine->run_cycles(10).error);
  CHECK(engine->cycle_count() == n + 10);
}

TEST_CASE("with privileges the cycle thread runs SCHED_FIFO on its CPU", "[cycle_engine]") {
  if (geteuid() != 0) {
    WARN("not root: the privileged path cannot be exercised here");
    return;
  }
  RecordingTask task(50);
  auto config = test_config(1000);
  config.cpu = std::thread::hardware_concurrency() > 1 ? 1 : 0;
  struct CpuTask : CycleTask {
    void run_cycle(const CycleContext&) noexcept override { cpu = sched_getcpu(); }
    std::atomic<int> cpu{-1};
  } cpu_task;
  auto engine = std::make_unique<CycleEngine>(config, cpu_task);
  auto r = engine->run_cycles(20);
  REQUIRE_FALSE(r.error);
  CHECK(r.warning.empty());
  CHECK(engine->realtime());
  INFO(engine->rt_status_text());
  CHECK(engine->rt_status_text().find("real-time: SCHED_FIFO 80") == 0);
  CHECK(engine->rt_status_text().find("memory locked") != std::string::npos);
  CHECK(cpu_task.cpu.load() == config.cpu);

  auto engine2 = std::make_unique<CycleEngine>(test_config(1000), task);
  REQUIRE_FALSE(engine2->run_cycles(20).error);
  for (std::size_t i = 0; i < 20; ++i) CHECK(task.entries[i].policy == SCHED_FIFO);
}

TEST_CASE("spin mode never starts a cycle before its deadline", "[cycle_engine]") {
  RecordingTask task(200);
  auto config = test_config(1000);
  config.spin_us = 100;
  auto engine = std::make_unique<CycleEngine>(config, task);
  REQUIRE_FALSE(engine->run_cycles(200).error);
  INFO(engine->rt_status_text());
  CHECK(engine->rt_status_text().find("spin 100 us") != std::string::npos);
  for (std::size_t i = 0; i < 200; ++i) {
    REQUIRE(task.entries[i].ctx.woke_ns >= task.entries[i].ctx.start_ns);
  }
  CHECK(engine->stats_snapshot().wake_latency.count == 200);
}

namespace {
// What the unprivileged child reports to the test.
struct FallbackReport {
  int stage = 0;  // 0 = ok, otherwise which step failed
  int start_error = 0;
  bool realtime = true;
  bool warned_first = false;
  bool warned_second = true;
  uint64_t cycles = 0;
  int policy_seen = -1;
  char status[512] = {};
  char warning[512] = {};
};

struct PolicyTask : CycleTask {
  void run_cycle(const CycleContext&) noexcept override {
    sched_param p{};
    int pol = -1;
    pthread_getschedparam(pthread_self(), &pol, &p);
    policy = pol;
  }
  std::atomic<int> policy{-1};
};

// Runs in the forked child: drop every privilege that would allow SCHED_FIFO or mlockall,
// then run the engine as configured for production.
FallbackReport run_unprivileged() {
  FallbackReport rep;
  const rlimit zero{0, 0};
  if (setrlimit(RLIMIT_RTPRIO, &zero) != 0 || setrlimit(RLIMIT_MEMLOCK, &zero) != 0) {
    rep.stage = 1;
    return rep;
  }
  if (geteuid() == 0) {
    // Leaving uid 0 clears the capability sets (CAP_SYS_NICE, CAP_IPC_LOCK).
    if (setgroups(0, nullptr) != 0 || setgid(65534) != 0 || setuid(65534) != 0) {
      rep.stage = 2;
      return rep;
    }
  }
  PolicyTask task;
  auto engine = std::make_unique<CycleEngine>(test_config(1000), task);
  auto first = engine->run_cycles(30);
  rep.start_error = first.error.value();
  rep.warned_first = !first.warning.empty();
  std::strncpy(rep.warning, first.warning.c_str(), sizeof(rep.warning) - 1);
  auto second = engine->run_cycles(10);  // warns once: not again
  rep.warned_second = !second.warning.empty();
  rep.realtime = engine->realtime();
  rep.cycles = engine->cycle_count();
  rep.policy_seen = task.policy.load();
  std::strncpy(rep.status, engine->rt_status_text().c_str(), sizeof(rep.status) - 1);
  return rep;
}
}  // namespace

TEST_CASE("without RT privileges the engine runs anyway and says why", "[cycle_engine]") {
  int fds[2];
  REQUIRE(pipe(fds) == 0);
  const pid_t pid = fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    close(fds[0]);
    const FallbackReport rep = run_unprivileged();
    const auto n = write(fds[1], &rep, sizeof(rep));
    _exit(n == static_cast<ssize_t>(sizeof(rep)) ? 0 : 3);
  }
  close(fds[1]);
  FallbackReport rep;
  std::size_t got = 0;
  while (got < sizeof(rep)) {
    const auto n = read(fds[0], reinterpret_cast<char*>(&rep) + got, sizeof(rep) - got);
    if (n <= 0) break;
    got += static_cast<std::size_t>(n);
  }
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  REQUIRE(WIFEXITED(status));
  REQUIRE(WEXITSTATUS(status) == 0);
  REQUIRE(got == sizeof(rep));
  REQUIRE(rep.stage == 0);

  INFO("status: " << rep.status);
  INFO("warning: " << rep.warning);
  CHECK(rep.start_error == 0);
  CHECK_FALSE(rep.realtime);
  CHECK(rep.cycles == 40);
  CHECK(rep.policy_seen == SCHED_OTHER);
  CHECK(rep.warned_first);
  CHECK_FALSE(rep.warned_second);
  const std::string text = rep.status;
  CHECK(text.find("not real-time") == 0);
  CHECK(text.find("SCHED_FIFO 80 refused (Operation not permitted)") != std::string::npos);
#ifdef DS1928_SANITIZER_BUILD
  // The sanitizers intercept mlockall and return success without locking (their terabytes of
  // shadow mapping cannot be locked): the refusal cannot show in this build.
  WARN("sanitizer build: mlockall is a no-op; the 'mlockall refused' text is not checked");
#else
  CHECK(text.find("mlockall refused") != std::string::npos);
#endif
  CHECK(std::string(rep.warning) == text);
}
