// Shared memory figures, each next to its baseline from the same run:
//  - read: one consistent read of an axis record (ds1928_shm_read_axis) by a process other than
//    the writer, while the writer publishes at 10 kHz; baseline: the textbook seqlock read of a
//    record of the same size (sequence, memcpy, fence, sequence) in the same conditions;
//  - publish: Publisher::publish() of all axes on the writer, without and with a reader asleep
//    in ds1928_shm_wait (woken by the wake-up thread); baseline: plain seqlock writes.
// Times are taken per operation with the TSC (serialised), calibrated against CLOCK_MONOTONIC;
// the figures include the median cost of an empty measurement, printed on the first line
// (subtracting it would credit the operation with overlap the serialisation does not allow).
// A third read figure is the first read after a wake-up, when the writer's core still holds the
// freshly written lines: the cost a control application synchronised to the daemon pays.
//
//   shm_bench [AXES=4] [READS=2000000] [PUBLISHES=200000]
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>
#include <x86intrin.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "ds1928/shm.hpp"
#include "shm/publisher.hpp"

using namespace ds1928;

namespace {

inline uint64_t tsc_begin() {
  _mm_lfence();
  return __rdtsc();
}
inline uint64_t tsc_end() {
  unsigned aux;
  const uint64_t t = __rdtscp(&aux);
  _mm_lfence();
  return t;
}

double tsc_per_ns() {
  const int64_t n0 = ds1928_shm_now_ns();
  const uint64_t t0 = __rdtsc();
  usleep(200'000);
  const int64_t n1 = ds1928_shm_now_ns();
  const uint64_t t1 = __rdtsc();
  return static_cast<double>(t1 - t0) / static_cast<double>(n1 - n0);
}

struct Figures {
  double p50 = 0, p99 = 0, max = 0;
};

Figures figures(std::vector<uint64_t>& ticks, double per_ns) {
  std::sort(ticks.begin(), ticks.end());
  auto at = [&](double q) {
    return static_cast<double>(
               ticks[static_cast<size_t>(q * static_cast<double>(ticks.size() - 1))]) /
           per_ns;
  };
  return {at(0.5), at(0.99), at(1.0)};
}

double timer_overhead() {
  std::vector<uint64_t> t(100'000);
  for (auto& x : t) {
    const uint64_t a = tsc_begin();
    x = tsc_end() - a;
  }
  std::sort(t.begin(), t.end());
  return static_cast<double>(t[t.size() / 2]);
}

// The baseline: a textbook seqlock record with the same payload size as ds1928_shm_axis.
struct alignas(64) PlainRecord {
  std::atomic<uint64_t> seq{0};
  uint64_t words[DS1928_AXIS_DATA_WORDS];
};

void plain_write(PlainRecord& r, const uint64_t* words) {
  const uint64_t s = r.seq.load(std::memory_order_relaxed);
  r.seq.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  std::memcpy(r.words, words, sizeof(r.words));
  r.seq.store(s + 2, std::memory_order_release);
}

void plain_read(const PlainRecord& r, uint64_t* out) {
  for (;;) {
    const uint64_t s1 = r.seq.load(std::memory_order_acquire);
    if (s1 & 1) continue;
    std::memcpy(out, const_cast<const uint64_t*>(r.words), sizeof(r.words));
    std::atomic_thread_fence(std::memory_order_acquire);
    if (r.seq.load(std::memory_order_relaxed) == s1) return;
  }
}

shm::AxisStatus status_for(uint64_t cycle, uint32_t axis) {
  shm::AxisStatus s;
  s.sample.position_raw = (cycle * 977 + axis) << 16;
  s.sample.periods = static_cast<int64_t>(cycle * 977 + axis);
  s.sample.fresh = true;
  s.validity = shm::AxisValidity::Valid;
  return s;
}

void print(const char* what, const Figures& ours, const Figures& base) {
  std::printf(
      "%-34s p50 %7.1f ns  p99 %7.1f ns  max %9.1f ns | baseline p50 %6.1f  p99 %7.1f"
      "  | p50 ratio %.2f\n",
      what, ours.p50, ours.p99, ours.max, base.p50, base.p99,
      base.p50 > 0 ? ours.p50 / base.p50 : 0.0);
}

}  // namespace

int main(int argc, char** argv) {
  const uint32_t axes = argc > 1 ? static_cast<uint32_t>(std::atoi(argv[1])) : 4;
  const size_t reads = argc > 2 ? static_cast<size_t>(std::atol(argv[2])) : 2'000'000;
  const size_t publishes = argc > 3 ? static_cast<size_t>(std::atol(argv[3])) : 200'000;
  const std::string name = "/ds1928d-bench-" + std::to_string(getpid());
  const double per_ns = tsc_per_ns();
  const double overhead = timer_overhead();
  std::printf("shm_bench: %u axes, TSC %.3f GHz, empty measurement %.1f ns (included below)\n",
              axes, per_ns, overhead / per_ns);

  // Baseline records in anonymous shared memory, visible to the forked writer.
  void* plain_map = mmap(nullptr, sizeof(PlainRecord) * axes, PROT_READ | PROT_WRITE,
                         MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  if (plain_map == MAP_FAILED) return 1;
  auto* plain = new (plain_map) PlainRecord[axes];

  int ready[2];
  if (pipe(ready) != 0) return 1;
  const pid_t writer = fork();
  if (writer == 0) {
    // Writer process: 10 kHz, both the real records and the baseline records every cycle.
    prctl(PR_SET_TIMERSLACK, 1UL);
    shm::Publisher pub;
    ShmConfig cfg;
    cfg.name = name;
    if (auto ec = pub.open(cfg, axes, 100'000)) {
      std::fprintf(stderr, "open %s: %s\n", name.c_str(), ec.message().c_str());
      _exit(1);
    }
    (void)!write(ready[1], "x", 1);
    std::vector<shm::AxisStatus> st(axes);
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (uint64_t c = 1;; ++c) {
      for (uint32_t a = 0; a < axes; ++a) st[a] = status_for(c, a);
      pub.publish(c, st);
      for (uint32_t a = 0; a < axes; ++a) {
        uint64_t w[DS1928_AXIS_DATA_WORDS] = {c, c, c, c, c, c, c, c, c};
        plain_write(plain[a], w);
      }
      next.tv_nsec += 100'000;
      if (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    }
  }
  char c;
  if (read(ready[0], &c, 1) != 1) return 1;

  ShmReader reader;
  if (auto ec = reader.open(name)) {
    std::fprintf(stderr, "map %s: %s\n", name.c_str(), ec.message().c_str());
    kill(writer, SIGKILL);
    return 1;
  }
  // Read latency, interleaved so that both see the same conditions.
  std::vector<uint64_t> ours(reads), base(reads);
  ds1928_axis_data d{};
  uint64_t words[DS1928_AXIS_DATA_WORDS];
  uint64_t sink = 0;
  for (size_t i = 0; i < reads; ++i) {
    const uint32_t axis = static_cast<uint32_t>(i % axes);
    uint64_t t0 = tsc_begin();
    (void)ds1928_shm_read_axis(&reader.header(), axis, &d);
    ours[i] = tsc_end() - t0;
    sink += d.position_raw;
    t0 = tsc_begin();
    plain_read(plain[axis], words);
    base[i] = tsc_end() - t0;
    sink += words[0];
  }
  print("consistent read (other process)", figures(ours, per_ns), figures(base, per_ns));

  // First read after each wake-up, order alternating so that neither side is always second.
  const size_t wakes = 2000;
  std::vector<uint64_t> ours_woken, base_woken;
  uint64_t seen = reader.wait_start();
  std::error_code ec;
  for (size_t i = 0; i < wakes; ++i) {
    if (reader.wait(seen, 1, ds1928_shm_now_ns() + 1'000'000'000, ec) != ShmWait::Published) break;
    for (int k = 0; k < 2; ++k) {
      if ((i + k) % 2 == 0) {
        const uint64_t t0 = tsc_begin();
        (void)ds1928_shm_read_axis(&reader.header(), 0, &d);
        ours_woken.push_back(tsc_end() - t0);
        sink += d.position_raw;
      } else {
        const uint64_t t0 = tsc_begin();
        plain_read(plain[axes > 1 ? 1 : 0], words);
        base_woken.push_back(tsc_end() - t0);
        sink += words[0];
      }
    }
  }
  kill(writer, SIGKILL);
  waitpid(writer, nullptr, 0);
  shm_unlink(name.c_str());
  shm_unlink((name + DS1928_SHM_WAIT_SUFFIX).c_str());
  if (!ours_woken.empty())
    print("first read after a wake-up", figures(ours_woken, per_ns), figures(base_woken, per_ns));

  // Publish cost on the writer side, in this process.
  shm::Publisher pub;
  ShmConfig cfg;
  cfg.name = name;
  if (auto ec = pub.open(cfg, axes, 100'000)) return 1;
  std::vector<shm::AxisStatus> st(axes);
  std::vector<uint64_t> pub_ticks(publishes), plain_ticks(publishes);
  for (size_t i = 0; i < publishes; ++i) {
    for (uint32_t a = 0; a < axes; ++a) st[a] = status_for(i, a);
    uint64_t t0 = tsc_begin();
    pub.publish(i + 1, st);
    pub_ticks[i] = tsc_end() - t0;
    t0 = tsc_begin();
    for (uint32_t a = 0; a < axes; ++a) {
      uint64_t w[DS1928_AXIS_DATA_WORDS] = {i, i, i, i, i, i, i, i, i};
      plain_write(plain[a], w);
    }
    plain_ticks[i] = tsc_end() - t0;
  }
  const Figures plain_publish = figures(plain_ticks, per_ns);
  print("publish, no waiter", figures(pub_ticks, per_ns), plain_publish);

  // With a reader asleep in the wait: the wake-up thread, not this one, makes the FUTEX_WAKE
  // (bench/shm/shm_wake_bench compares it with the former inline wake).
  ShmReader waiter_map;
  if (auto ec = waiter_map.open(name)) return 1;
  std::atomic<bool> stop{false};
  std::thread waiter([&] {
    uint64_t seen = waiter_map.wait_start();
    std::error_code ec;
    while (!stop.load()) (void)waiter_map.wait(seen, 1, ds1928_shm_now_ns() + 100'000'000, ec);
  });
  const size_t woken = std::min<size_t>(publishes, 20'000);
  std::vector<uint64_t> wake_ticks;
  wake_ticks.reserve(woken);
  const uint64_t calls0 = pub.wake_calls();
  for (size_t i = 0; i < woken; ++i) {
    usleep(100);  // let the waiter fall asleep again
    for (uint32_t a = 0; a < axes; ++a) st[a] = status_for(i, a);
    const uint64_t t0 = tsc_begin();
    pub.publish(publishes + i + 1, st);
    wake_ticks.push_back(tsc_end() - t0);
  }
  stop = true;
  waiter.join();
  const Figures with_waiter = figures(wake_ticks, per_ns);
  std::printf("%-34s p50 %7.1f ns  p99 %7.1f ns  max %9.1f ns | %llu of %zu publications woke\n",
              "publish, a reader asleep (woken by the wake-up thread)", with_waiter.p50,
              with_waiter.p99, with_waiter.max,
              static_cast<unsigned long long>(pub.wake_calls() - calls0), woken);
  std::printf("(checksum %llu)\n", static_cast<unsigned long long>(sink & 1));
  return 0;
}
