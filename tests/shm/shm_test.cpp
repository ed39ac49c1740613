// Shared memory: layout, publisher life cycle, consistent reads, waiting, restart and death.
#include "ds1928/shm.hpp"

#include <sys/stat.h>
#include <sys/syscall.h>

#include <catch2/catch.hpp>
#include <thread>

#include "shm/shm_error.hpp"
#include "shm_test_util.hpp"
#include "support/alloc_counter.hpp"
#include "support/syscall_counter.hpp"
#include "support/wait.hpp"

using namespace ds1928;
using namespace ds1928::shm;
using namespace ds1928::shm::test;

namespace {

mode_t object_mode(const std::string& name) {
  struct stat st {};
  if (stat(("/dev/shm" + name).c_str(), &st) != 0) return 0;
  return st.st_mode & 07777;
}

}  // namespace

TEST_CASE("publisher creates the objects with the configured mode and removes them") {
  const auto name = unique_name("mode");
  ShmConfig cfg = config_for(name);
  cfg.mode = 0640;
  {
    Publisher pub;
    REQUIRE_FALSE(pub.open(cfg, 3, 1'000'000));
    CHECK(object_mode(name) == 0640);
    CHECK(object_mode(name + ".wait") == 0660);  // readers register there

    ShmReader reader;
    REQUIRE_FALSE(reader.open(name));
    const auto& h = reader.header();
    CHECK(h.magic == DS1928_SHM_MAGIC);
    CHECK(h.abi_version == DS1928_SHM_ABI_VERSION);
    CHECK(h.header_size == sizeof(ds1928_shm_header));
    CHECK(h.record_size == sizeof(ds1928_shm_axis));
    CHECK(h.axis_count == 3);
    CHECK(h.cycle_period_ns == 1'000'000);
    CHECK(h.daemon_pid == getpid());
    CHECK(h.generation == pub.generation());
    CHECK(reader.daemon_state() == DS1928_DAEMON_STARTING);
    CHECK(reader.can_wait());

    ds1928_axis_data d{};
    REQUIRE_FALSE(reader.read(2, d));
    CHECK(d.validity == DS1928_AXIS_BUS_DOWN);  // nothing published yet
    CHECK(reader.read(3, d) == std::errc::invalid_argument);
  }
  CHECK(object_mode(name) == 0);
  CHECK(object_mode(name + ".wait") == 0);
}

TEST_CASE("publisher rejects bad parameters with precise errors") {
  Publisher pub;
  CHECK(pub.open(config_for("no-slash"), 1, 1000) == ShmError::kInvalidName);
  CHECK(pub.open(config_for("/a/b"), 1, 1000) == ShmError::kInvalidName);
  CHECK(pub.open(config_for("/" + std::string(300, 'x')), 1, 1000) == ShmError::kInvalidName);
  CHECK(pub.open(config_for(unique_name("bad")), kMaxAxes + 1, 1000) == ShmError::kTooManyAxes);
  ShmConfig cfg = config_for(unique_name("bad"));
  cfg.group = "no-such-group-ds1928";
  CHECK(pub.open(cfg, 1, 1000) == ShmError::kUnknownGroup);
  CHECK_FALSE(pub.is_open());
}

TEST_CASE("a daemon without axes publishes the header alone") {
  const auto name = unique_name("none");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 0, 1000));
  ds1928_shm_reader r{};
  REQUIRE(ds1928_shm_reader_open(&r, name.c_str()) == 0);
  CHECK(r.header->axis_count == 0);
  ds1928_shm_reader_close(&r);
  pub.close();
}

TEST_CASE("a reader gets exactly what was published, field by field") {
  const auto name = unique_name("fields");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 2, 500'000));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));

  AxisStatus a0 = status_for(41, 0);
  a0.sample.position_raw = 0x0123'4567'89ab'cde8ull;
  a0.sample.position_sdc = static_cast<int32_t>(0x89ab'cde8u);
  a0.sample.periods = -5;
  a0.sample.fraction = 0xcde8;
  a0.sample.fraction_valid = false;
  a0.sample.time_source = TimeSource::RxTimestamp;
  a0.sample.pos_cycle = -3;
  a0.sample.new_position = true;
  a0.sample.error_info = error_info::kEnDatComError;
  a0.endat_error = 0xbeef;
  a0.endat_warning = 0x12;
  a0.errors = assess(error_policy(), ErrorWords{a0.sample.error_info, 0xbeef, 0x12});
  a0.validity = classify(a0.sample, true, a0.errors);
  const AxisStatus a1 = status_for(41, 1);
  const AxisStatus all[] = {a0, a1};
  const int64_t before = now_ns();
  pub.publish(41, all);

  ds1928_axis_data d{};
  REQUIRE_FALSE(reader.read(0, d));
  CHECK(d.position_raw == 0x0123'4567'89ab'cde8ull);
  CHECK(d.position_sdc == static_cast<int32_t>(0x89ab'cde8u));
  CHECK(d.periods == -5);
  CHECK(d.fraction == 0xcde8);
  CHECK(d.time_source == DS1928_TIME_RX_TIMESTAMP);
  CHECK(d.pos_cycle == -3);
  // 0xbeef: EnDatError faults; 0x12: EnDatWarning temperature (a warning).
  CHECK(d.flags ==
        (DS1928_AXIS_NEW_POSITION | DS1928_AXIS_FRESH | DS1928_AXIS_FAULT | DS1928_AXIS_WARNING));
  CHECK(d.error_info == error_info::kEnDatComError);
  CHECK(d.endat_error == 0xbeef);
  CHECK(d.endat_warning == 0x12);
  CHECK(d.validity == DS1928_AXIS_MODULE_ERROR);
  CHECK(d.cycle == 41);
  CHECK(d.publish_ns >= before);
  CHECK(d.check == ds1928_shm_check(&d));
  REQUIRE_FALSE(reader.read(1, d));
  CHECK(consistent(d, 1));
  CHECK(d.flags == (DS1928_AXIS_NEW_POSITION | DS1928_AXIS_FRACTION_VALID | DS1928_AXIS_FRESH));

  CHECK(reader.daemon_state() == DS1928_DAEMON_RUNNING);
  CHECK(ds1928_shm_last_cycle(&reader.header()) == 41);
  CHECK(ds1928_shm_publish_count(&reader.header()) == 1);
  CHECK(ds1928_shm_last_publish_ns(&reader.header()) == d.publish_ns);
  CHECK(reader.daemon_alive());

  d.periods ^= 1;  // the check value catches a changed word
  CHECK(d.check != ds1928_shm_check(&d));
}

TEST_CASE("validity classification follows bus, the error bits' effect, freshness") {
  const ErrorPolicy p = error_policy();
  const auto errors = [&p](uint8_t ei) { return assess(p, ErrorWords{ei, 0, 0}); };
  AxisSample s;
  s.fresh = true;
  CHECK(classify(s, true, errors(0)) == AxisValidity::Valid);
  CHECK(classify(s, false, errors(0)) == AxisValidity::BusDown);
  CHECK(classify(s, true, errors(error_info::kEnDatComError)) == AxisValidity::ModuleError);
  // A warning leaves a fresh position valid.
  CHECK(classify(s, true, errors(error_info::kEnDatRefWarning)) == AxisValidity::Valid);
  s.fresh = false;
  CHECK(classify(s, true, errors(error_info::kEnDatComError)) == AxisValidity::Stale);
  // An analogue error holds (apply_error_policy: not fresh, held): stale.
  s.held = true;
  CHECK(classify(s, true, errors(error_info::kVssCheckError)) == AxisValidity::Stale);
  CHECK(classify(s, true, errors(error_info::kVssCheckError | error_info::kEnDatComError)) ==
        AxisValidity::ModuleError);
}

TEST_CASE("publishing allocates nothing, takes no mutex, and makes no futex call without waiters") {
  const auto name = unique_name("rt");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 4, 100'000));
  std::vector<AxisStatus> st(4);
  ds1928::test::HeapCounts counts;
  {
    ds1928::test::ScopedCounting scope;
    for (uint64_t c = 1; c <= 10'000; ++c) {
      for (uint32_t a = 0; a < 4; ++a) st[a] = status_for(c, a);
      pub.publish(c, st);
    }
    counts = scope.stop();
  }
  CHECK(counts.allocations() == 0);
  CHECK(counts.mutex_locks == 0);
  if (!ds1928::test::counts_mutexes())
    WARN("TSan build: mutex locks are not counted; that check is void");
  CHECK(pub.wake_calls() == 0);
  CHECK(pub.doorbell_calls() == 0);
  CHECK_FALSE(pub.waker_active());
}

namespace {

// Readers in threads of their own, each sleeping in ds1928_shm_wait with its factor and
// counting the publications it got.
class SleepingReaders {
 public:
  SleepingReaders(const std::string& name, const std::vector<uint32_t>& factors)
      : got_(factors.size()) {
    for (std::size_t i = 0; i < factors.size(); ++i) {
      threads_.emplace_back([this, name, i, every = factors[i]] {
        ShmReader reader;
        if (reader.open(name)) return;
        uint64_t seen = reader.wait_start();
        std::error_code ec;
        while (!stop_.load()) {
          const auto r = reader.wait(seen, every, now_ns() + 200'000'000, ec);
          if (r == ShmWait::Published) got_[i].fetch_add(1);
          if (r == ShmWait::Stopped) break;
        }
      });
    }
  }
  ~SleepingReaders() {
    stop_ = true;
    for (auto& t : threads_) t.join();
  }
  [[nodiscard]] uint64_t got(std::size_t i) const { return got_[i].load(); }
  [[nodiscard]] uint64_t least() const {
    uint64_t m = UINT64_MAX;
    for (const auto& g : got_) m = std::min(m, g.load());
    return m;
  }

 private:
  std::vector<std::atomic<uint64_t>> got_;
  std::atomic<bool> stop_{false};
  std::vector<std::thread> threads_;
};

void sleep_until_ns(int64_t t) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(t % 1'000'000'000);
  clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

}  // namespace

TEST_CASE("with readers asleep, publishing makes no system call: the wake-up thread wakes them") {
  const auto name = unique_name("nosys");
  Publisher pub;
  const int64_t period = 200'000;
  REQUIRE_FALSE(pub.open(config_for(name), 4, period));
  // One reader, or sixteen in every slot (factors 1..16).
  const unsigned readers = GENERATE(1u, 16u);
  std::vector<uint32_t> factors;
  for (unsigned i = 0; i < readers; ++i) factors.push_back(i + 1);
  SleepingReaders sleeping(name, factors);

  std::atomic<uint64_t> trapped{UINT64_MAX}, last_nr{0}, doorbells_in_window{UINT64_MAX};
  std::atomic<uint64_t> wakes_before{0}, got_before{0};
  std::atomic<bool> filtered{false};
  constexpr uint64_t kWarmup = 2'000, kCounted = 2'000;
  std::thread cycle([&] {
    std::vector<AxisStatus> st(4);
    int64_t next = now_ns();
    uint64_t c = 1;
    // Warm-up: every reader asleep and woken at least once (the waker has been rung).
    for (; c <= kWarmup || (sleeping.least() == 0 && c < 50'000); ++c) {
      next += period;
      sleep_until_ns(next);
      for (uint32_t a = 0; a < 4; ++a) st[a] = status_for(c, a);
      pub.publish(c, st, next + period);
    }
    got_before = sleeping.got(0);
    wakes_before = pub.wake_calls();
    const uint64_t doorbells = pub.doorbell_calls();
    const uint64_t trapped_before = ds1928::test::SyscallCounter::trapped();
    filtered = ds1928::test::SyscallCounter::trap_all_but({SYS_clock_nanosleep, SYS_clock_gettime});
    // At least kCounted publications, and on until the readers were woken 20 times more (a
    // bound that only stops a hung test): how often the scheduler lets the reader threads run
    // on a loaded machine is not what is counted here.
    const uint64_t end = c + kCounted;
    const int64_t give_up = now_ns() + 60'000'000'000;
    for (; c < end || (sleeping.got(0) < got_before + 20 && now_ns() < give_up); ++c) {
      next += period;
      sleep_until_ns(next);
      for (uint32_t a = 0; a < 4; ++a) st[a] = status_for(c, a);
      pub.publish(c, st, next + period);
    }
    trapped = ds1928::test::SyscallCounter::trapped() - trapped_before;
    last_nr = static_cast<uint64_t>(ds1928::test::SyscallCounter::last_nr());
    doorbells_in_window = pub.doorbell_calls() - doorbells;
  });
  cycle.join();
  REQUIRE(filtered);
  INFO(readers << " reader(s); last trapped system call number " << last_nr.load());
  CHECK(trapped == 0);
  CHECK(doorbells_in_window == 0);
  CHECK(pub.waker_active());
  // The readers really slept and were woken meanwhile, by the wake-up thread.
  CHECK(sleeping.got(0) >= got_before + 20);
  CHECK(pub.wake_calls() >= wakes_before + 20);
}

TEST_CASE("the wake-up thread goes idle without readers and is rung by the next one") {
  const auto name = unique_name("idle");
  Publisher pub;
  const int64_t period = 1'000'000;
  REQUIRE_FALSE(pub.open(config_for(name), 1, period));
  std::vector<AxisStatus> st(1);
  uint64_t c = 0;
  auto publish_until = [&](auto done, int64_t limit_ns) {
    const int64_t deadline = now_ns() + limit_ns;
    while (!done() && now_ns() < deadline) {
      ++c;
      st[0] = status_for(c, 0);
      pub.publish(c, st);
      std::this_thread::yield();  // the loop waits on done(), bounded, never on time passing
    }
    return done();
  };
  REQUIRE(publish_until([] { return false; }, 20'000'000) == false);
  CHECK_FALSE(pub.waker_active());
  CHECK(pub.doorbell_calls() == 0);
  {
    SleepingReaders sleeping(name, {1});
    REQUIRE(publish_until([&] { return sleeping.got(0) >= 20; }, 10'000'000'000));
    CHECK(pub.doorbell_calls() == 1);  // one ring for the transition, not one per cycle
    CHECK(pub.waker_active());
  }
  // No reader for more than a second: idle again (bounded wait instead of a timing assertion).
  REQUIRE(publish_until([&] { return !pub.waker_active(); }, 20'000'000'000));
  const uint64_t wakes = pub.wake_calls();
  {
    SleepingReaders sleeping(name, {3});
    REQUIRE(publish_until([&] { return sleeping.got(0) >= 5; }, 10'000'000'000));
    CHECK(pub.doorbell_calls() == 2);
    CHECK(pub.wake_calls() > wakes);
  }
}

TEST_CASE("a waiting reader is woken at every publication, and with a factor only on multiples") {
  const auto name = unique_name("factor");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 1, 1'000'000));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  ShmProbe probe(name);
  REQUIRE(probe.is_open());
  const uint32_t every = GENERATE(1u, 4u);
  const uint64_t cycles = 200;
  const uint64_t expected = cycles / every;

  std::vector<uint64_t> woke;
  woke.reserve(cycles);
  std::atomic<uint64_t> woke_count{0};
  std::atomic<pid_t> waiter_tid{0};
  std::thread waiter([&] {
    waiter_tid = static_cast<pid_t>(syscall(SYS_gettid));
    uint64_t seen = reader.wait_start();
    std::error_code ec;
    while (reader.wait(seen, every, now_ns() + 10'000'000'000, ec) == ShmWait::Published) {
      woke.push_back(seen);
      woke_count.store(woke.size(), std::memory_order_release);
      if (seen >= cycles) break;
    }
  });
  struct Joiner {
    std::thread& t;
    ~Joiner() {
      if (t.joinable()) t.join();
    }
  } joiner{waiter};

  // Lock step instead of a pace: each publication waits until the waiter consumed every
  // earlier due one and sleeps in the futex again, so every due publication must wake it
  // exactly once, whatever the scheduler does. A generous deadline only turns a lost wake-up
  // into a failure instead of a hang.
  std::vector<AxisStatus> st(1);
  bool in_step = true;
  for (uint64_t c = 1; c <= cycles && in_step; ++c) {
    const uint64_t due_before = (c - 1) / every;
    const int64_t deadline = now_ns() + 10'000'000'000;
    while (!(woke_count.load(std::memory_order_acquire) >= due_before &&
             probe.waiters(every) == 1 && thread_sleeping(waiter_tid.load()))) {
      if (now_ns() > deadline) {
        in_step = false;
        break;
      }
      std::this_thread::yield();
    }
    INFO("before cycle " << c << ": " << woke_count.load() << " wake-ups, " << due_before
                         << " due");
    CHECK(in_step);
    st[0] = status_for(c, 0);
    pub.publish(c, st);
  }
  waiter.join();

  // Exactly the due publications, each once, in order; never one off the asked rate.
  std::vector<uint64_t> due;
  for (uint64_t c = every; c <= cycles; c += every) due.push_back(c);
  CHECK(woke == due);
  // The daemon side issued one wake-up per due publication, not one per cycle.
  CHECK(pub.wake_calls() == expected);
}

TEST_CASE("a waiting reader never misses the last publication of a free-running writer") {
  const auto name = unique_name("paced");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 1, 1'000'000));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  const uint32_t every = GENERATE(1u, 4u);
  const uint64_t cycles = 200;
  const uint64_t expected = cycles / every;

  // The writer does not wait for the reader: wake-ups race with the reader's way back into
  // the futex. A reader that oversleeps gets the newer publication at once (merged), so only
  // what holds on any schedule is checked: no wake-up without a due publication in between,
  // none lost at the end, no more wake calls than due publications.
  std::vector<uint64_t> woke;
  woke.reserve(cycles);
  std::atomic<bool> ready{false};
  std::thread waiter([&] {
    uint64_t seen = reader.wait_start();
    ready = true;
    std::error_code ec;
    while (reader.wait(seen, every, now_ns() + 10'000'000'000, ec) == ShmWait::Published) {
      woke.push_back(seen);
      if (seen >= cycles) break;
    }
  });
  while (!ready) std::this_thread::yield();
  std::vector<AxisStatus> st(1);
  timespec next{};
  clock_gettime(CLOCK_MONOTONIC, &next);
  for (uint64_t c = 1; c <= cycles; ++c) {
    st[0] = status_for(c, 0);
    next.tv_nsec += 200'000;
    if (next.tv_nsec >= 1'000'000'000) {
      next.tv_nsec -= 1'000'000'000;
      ++next.tv_sec;
    }
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    pub.publish(c, st);
  }
  waiter.join();

  REQUIRE_FALSE(woke.empty());
  CHECK(woke.back() == cycles);
  CHECK(woke.size() <= expected);
  CHECK(woke.front() >= every);
  for (size_t i = 1; i < woke.size(); ++i) {
    INFO("wake-up " << i << ": cycle " << woke[i] << " after " << woke[i - 1]);
    CHECK(woke[i] / every > woke[i - 1] / every);  // a due publication lies in between
  }
  CHECK(pub.wake_calls() <= expected);
}

TEST_CASE("a waiter times out when publications stop and returns 'stopped' when the daemon exits") {
  const auto name = unique_name("stop");
  const ObjectsRemover remover{name};  // the writer dies without removing them
  WriterProcess writer;
  // 100 cycles at 1 ms, then alive but silent for 400 ms (hung), then exits without close.
  writer.start(name, 1, 1'000'000, 100, false, 400);
  REQUIRE(writer.running());
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  uint64_t seen = reader.wait_start();
  std::error_code ec;
  int published = 0;
  ShmWait r;
  int64_t t0 = 0;
  // A writer descheduled for 50 ms on a loaded machine makes a wait time out early: that is a
  // right answer too, so the reader waits on until the writer's last cycle was seen. Only the
  // timeout after it is the one under test.
  const int64_t give_up = now_ns() + 30'000'000'000;
  for (;;) {
    t0 = now_ns();
    r = reader.wait(seen, 1, t0 + 50'000'000, ec);
    if (r == ShmWait::Published) {
      ++published;
      continue;
    }
    if (r == ShmWait::Timeout && seen < 100 && now_ns() < give_up) continue;
    break;
  }
  const int64_t waited = now_ns() - t0;
  CHECK_FALSE(ec);
  CHECK(r == ShmWait::Timeout);
  CHECK(seen == 100);
  CHECK(published >= 10);          // woken across processes (merged wake-ups allowed under load)
  CHECK(waited >= 50'000'000);     // never before the deadline
  CHECK(waited < 30'000'000'000);  // and returns after it (a bound for stalls, not a timing)
  // The daemon counts as dead once 100 ms passed since the last publication.
  CHECK(ds1928::test::wait_until([&] { return !reader.daemon_alive(); }));
  CHECK(reader.daemon_state() == DS1928_DAEMON_RUNNING);  // it never said goodbye
  writer.join();

  // A clean stop wakes a sleeping waiter at once.
  const auto name2 = unique_name("stop2");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name2), 1, 1'000'000));
  ShmReader reader2;
  REQUIRE_FALSE(reader2.open(name2));
  std::atomic<int> result{-1};
  std::atomic<pid_t> waiter_tid{0};
  std::thread waiter([&] {
    waiter_tid = static_cast<pid_t>(syscall(SYS_gettid));
    uint64_t s = reader2.wait_start();
    std::error_code e;
    result = static_cast<int>(reader2.wait(s, 1, now_ns() + 60'000'000'000, e));
  });
  // Close once the waiter is asleep in the futex (the case under test), not before.
  REQUIRE(ds1928::test::wait_until([&] { return thread_sleeping(waiter_tid.load()); }));
  const int64_t t1 = now_ns();
  pub.close();
  waiter.join();
  // Stopped, not Timeout: the close woke it (its deadline is a minute away).
  CHECK(result == static_cast<int>(ShmWait::Stopped));
  CHECK(now_ns() - t1 < 30'000'000'000);
  CHECK_FALSE(reader2.daemon_alive());
}

TEST_CASE("a reader detects a restarted daemon by its generation") {
  const auto name = unique_name("restart");
  auto first = std::make_unique<Publisher>();
  REQUIRE_FALSE(first->open(config_for(name), 1, 1'000'000));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  const uint64_t gen1 = reader.generation();
  CHECK_FALSE(reader.reopen());  // same daemon
  first.reset();
  CHECK(reader.daemon_state() == DS1928_DAEMON_STOPPED);  // the old mapping stays readable
  CHECK_FALSE(reader.reopen());                           // nobody there yet

  Publisher second;
  REQUIRE_FALSE(second.open(config_for(name), 2, 1'000'000));
  REQUIRE(reader.reopen());
  CHECK(reader.generation() != gen1);
  CHECK(reader.generation() == second.generation());
  CHECK(reader.axis_count() == 2);
  CHECK(reader.daemon_state() == DS1928_DAEMON_STARTING);
}

TEST_CASE("a second daemon cannot take over a live daemon's name, but replaces a dead one's") {
  const auto name = unique_name("inuse");
  const ObjectsRemover remover{name};
  {
    WriterProcess live;
    live.fifo_priority = 20;  // keeps publishing on a loaded machine: alive for sure
    live.start(name, 1, 1'000'000, 0, true);  // publishes until killed
    REQUIRE(live.running());
    Publisher pub;
    CHECK(pub.open(config_for(name), 1, 1'000'000) == ShmError::kNameInUse);
    live.stop(false);  // killed: its objects stay behind
  }
  Publisher pub;
  CHECK_FALSE(pub.open(config_for(name), 1, 1'000'000));
  CHECK(pub.is_open());
}
