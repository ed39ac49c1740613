// Which CPU stood still, and when: one SCHED_FIFO thread per CPU of the process' affinity, pinned,
// at the highest priority given (99 by default: nothing of this machine preempts it but the
// kernel's own stop work), waking every period and writing down each wake-up later than the
// threshold. A thread that cannot wake at that priority was stopped by what the machine does not
// schedule: its host not running the vCPU. A test lines these spans up with what it saw stop
// (an MN's SoCs absent on the wire) to say whose stall it was.
//
//   host_stall_probe --out FILE [--period-us 1000] [--threshold-us 1000] [--priority 99]
//
// Prints "probing N CPU(s) ..." once every CPU's thread measures, runs until SIGINT or SIGTERM,
// then writes one line per stall, ordered by start:
//   CPU START END LATE_MS      (START/END: CLOCK_REALTIME seconds, the capture files' clock;
//                               START = the wake-up that was due, END = when it came)
// and on stdout a summary: per CPU the stalls and the longest, and how many stalls overlapped a
// stall of every other CPU (the whole machine stopped).
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "core/clock.hpp"
#include "core/rt_setup.hpp"

namespace {

std::atomic<bool> g_stop{false};

void on_signal(int) {
  g_stop.store(true);
}

struct Stall {
  int cpu = 0;
  int64_t start_real_ns = 0;  // the wake-up that was due
  int64_t end_real_ns = 0;    // when it came
};

struct Options {
  std::string out;
  int64_t period_ns = 1'000'000;
  int64_t threshold_ns = 1'000'000;
  int priority = 99;
};

// Fixed room per CPU: a probe that allocated while measuring would measure its allocator.
constexpr std::size_t kMaxStallsPerCpu = 100'000;

void probe(int cpu, const Options& o, std::vector<Stall>& stalls, std::atomic<int>& failed,
           std::atomic<std::size_t>& measuring) {
  namespace rt = ds1928::rt;
  if (!rt::pin_to_cpu(cpu).ok() || !rt::set_fifo_priority(o.priority).ok()) {
    failed.store(cpu + 1);
    return;
  }
  int64_t due = rt::now_ns();
  measuring.fetch_add(1);
  while (!g_stop.load(std::memory_order_relaxed)) {
    due += o.period_ns;
    const int64_t now = rt::sleep_until(due);
    const int64_t late = now - due;
    if (late >= o.threshold_ns) {
      const int64_t real_now = rt::realtime_ns() - (rt::now_ns() - now);
      if (stalls.size() < stalls.capacity()) stalls.push_back({cpu, real_now - late, real_now});
    }
    if (late > o.period_ns) due = now;  // one stall, one line: no catching up
  }
}

int usage() {
  std::fprintf(stderr,
               "usage: host_stall_probe --out FILE [--period-us N] [--threshold-us N] "
               "[--priority P]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return usage();
    const char* v = argv[++i];
    if (a == "--out") {
      o.out = v;
    } else if (a == "--period-us") {
      o.period_ns = std::atoll(v) * 1000;
    } else if (a == "--threshold-us") {
      o.threshold_ns = std::atoll(v) * 1000;
    } else if (a == "--priority") {
      o.priority = std::atoi(v);
    } else {
      return usage();
    }
  }
  if (o.out.empty() || o.period_ns <= 0 || o.threshold_ns <= 0 || o.priority < 1 || o.priority > 99)
    return usage();
  std::FILE* out = std::fopen(o.out.c_str(), "w");
  if (out == nullptr) {
    std::perror(o.out.c_str());
    return 1;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  if (const auto locked = ds1928::rt::lock_all_memory(); !locked.ok())
    std::fprintf(stderr, "host_stall_probe: mlockall: %s\n", std::strerror(locked.error));

  std::vector<int> cpus;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (ds1928::rt::cpu_usable(c)) cpus.push_back(c);
  std::vector<std::vector<Stall>> per_cpu(cpus.size());
  for (auto& v : per_cpu) v.reserve(kMaxStallsPerCpu);
  std::atomic<int> failed{0};
  std::atomic<std::size_t> measuring{0};
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < cpus.size(); ++i)
    threads.emplace_back(probe, cpus[i], std::cref(o), std::ref(per_cpu[i]), std::ref(failed),
                         std::ref(measuring));
  // The line below says every CPU is watched from here on: whoever starts the probe can wait for
  // it before the span it wants covered (the probe's test stops it only after this line).
  while (measuring.load() < cpus.size() && failed.load() == 0 && !g_stop.load())
    (void)ds1928::rt::sleep_until(ds1928::rt::now_ns() + 1'000'000);
  if (failed.load() != 0)
    g_stop.store(true);  // the others stop too: the run is void
  else
    std::printf("probing %zu CPU(s) every %lld us at SCHED_FIFO %d, stalls from %lld us\n",
                cpus.size(), static_cast<long long>(o.period_ns / 1000), o.priority,
                static_cast<long long>(o.threshold_ns / 1000));
  std::fflush(stdout);
  for (auto& t : threads) t.join();
  if (failed.load() != 0) {
    std::fprintf(stderr, "host_stall_probe: CPU %d: SCHED_FIFO %d or affinity refused (root?)\n",
                 failed.load() - 1, o.priority);
    return 1;
  }

  std::vector<Stall> all;
  for (const auto& v : per_cpu) all.insert(all.end(), v.begin(), v.end());
  std::sort(all.begin(), all.end(),
            [](const Stall& a, const Stall& b) { return a.start_real_ns < b.start_real_ns; });
  for (const Stall& s : all)
    std::fprintf(out, "%d %.6f %.6f %.3f\n", s.cpu, static_cast<double>(s.start_real_ns) / 1e9,
                 static_cast<double>(s.end_real_ns) / 1e9,
                 static_cast<double>(s.end_real_ns - s.start_real_ns) / 1e6);
  std::fclose(out);

  // A stall of every CPU at once: each other CPU has a stall overlapping it.
  std::size_t whole = 0;
  for (const Stall& s : all) {
    bool every = true;
    for (std::size_t i = 0; i < per_cpu.size() && every; ++i) {
      if (cpus[i] == s.cpu) continue;
      every = std::any_of(per_cpu[i].begin(), per_cpu[i].end(), [&](const Stall& o2) {
        return o2.start_real_ns < s.end_real_ns && s.start_real_ns < o2.end_real_ns;
      });
    }
    if (every && cpus.size() > 1) ++whole;
  }
  for (std::size_t i = 0; i < cpus.size(); ++i) {
    int64_t longest = 0;
    for (const Stall& s : per_cpu[i]) longest = std::max(longest, s.end_real_ns - s.start_real_ns);
    std::printf("cpu %d: %zu stalls%s, longest %.3f ms\n", cpus[i], per_cpu[i].size(),
                per_cpu[i].size() == kMaxStallsPerCpu ? " (room full: more not written)" : "",
                static_cast<double>(longest) / 1e6);
  }
  std::printf("stalls overlapping a stall of every other CPU: %zu of %zu\n", whole, all.size());
  return 0;
}
