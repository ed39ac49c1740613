// The cycle's cost model, part "axes × readers": the daemon's whole cycle work (CycleWork: the
// exchange with the built-in simulated bus, decoding, Flatstream tunnels, shared-memory
// publication) on the cycle engine (SCHED_FIFO, pinned, the publisher's wake-up thread one
// priority below on the same CPU, as in ds1928d), for 1, 4 and 16 axes and 0, 1 and 16 readers
// asleep in ds1928_shm_wait (factor 1). Reported: the engine's own work histogram (run_cycle per
// cycle, p50/p99/max µs), the engine's wake-up latency p99, overruns, and the per-axis slope.
// On the simulated bus the exchange includes the simulated module itself (its EnDat encoder
// model runs in the exchange), so the per-axis slope is an upper bound of the daemon's own.
// The part "CNs" (the POWERLINK exchange) is measured by bench/powerlink/run_cycle_bench.sh.
//
//   cycle_cost_bench [--period-us 1000] [--cycles 5000] [--cpu 1] [--priority 80]
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "core/cycle_engine.hpp"
#include "cycle_work.hpp"
#include "ds1928/shm.h"
#include "shm/publisher.hpp"
#include "sim/simulated_bus.hpp"

using namespace ds1928;

namespace {

struct Point {
  double p50 = 0, p99 = 0, max = 0, wake_p99 = 0;
  uint64_t overruns = 0, wake_calls = 0, rings = 0;
};

double us(int64_t ns) {
  return static_cast<double>(ns) / 1000.0;
}

Point run(uint32_t axes, unsigned readers, uint32_t period_us, uint64_t cycles, int cpu, int prio) {
  DaemonConfig c;
  c.cycle.period_us = period_us;
  c.cycle.cpu = cpu;
  c.cycle.rt_priority = prio;
  c.cycle.hold_cpu_dma_latency = true;
  c.axes.resize(axes);
  for (uint32_t i = 0; i < axes; ++i) {
    c.axes[i].name = "axis" + std::to_string(i);
    c.axes[i].slot = static_cast<uint8_t>(i + 1);
  }
  c.simulated.axes.resize(axes);
  c.shm.name = "/ds1928d-costbench-" + std::to_string(getpid());
  sim::SimulatedBus bus(c.axes, c.simulated);
  if (bus.start()) return {};
  shm::Publisher publisher;
  if (publisher.open(c.shm, axes, uint64_t{period_us} * 1000)) return {};
  CycleWork work(c, bus, publisher);

  std::atomic<bool> stop{false};
  std::vector<std::thread> threads;
  for (unsigned r = 0; r < readers; ++r) {
    threads.emplace_back([&] {
      sched_param sp{};
      sp.sched_priority = prio - 10;
      pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
      ds1928_shm_reader reader{};
      if (ds1928_shm_reader_open(&reader, c.shm.name.c_str()) != 0) return;
      uint64_t seen = ds1928_shm_wait_start(reader.header);
      while (!stop.load())
        (void)ds1928_shm_wait(&reader, &seen, 1, ds1928_shm_now_ns() + 100'000'000);
      ds1928_shm_reader_close(&reader);
    });
  }
  CycleEngine engine(c.cycle, work);
  // Warm-up (readers asleep, the wake-up thread rung), then the measured run.
  (void)engine.run_cycles(500);
  (void)publisher.place_waker(prio - 1, cpu);
  engine.request_stats_reset();
  (void)engine.run_cycles(cycles);
  const auto s = engine.stats_snapshot();
  const uint64_t wake_calls = publisher.wake_calls();  // before close() wakes everyone once
  stop = true;
  publisher.close();  // wakes the readers with "stopped"
  for (auto& t : threads) t.join();
  Point p;
  p.p50 = us(s.work.p50_ns);
  p.p99 = us(s.work.p99_ns);
  p.max = us(s.work.max_ns);
  p.wake_p99 = us(s.wake_latency.p99_ns);
  p.overruns = s.overruns;
  p.wake_calls = wake_calls;
  p.rings = publisher.doorbell_calls();
  return p;
}

}  // namespace

int main(int argc, char** argv) {
  uint32_t period_us = 1000;
  uint64_t cycles = 5000;
  int cpu = 1, prio = 80;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const long v = std::atol(argv[i + 1]);
    if (k == "--period-us")
      period_us = static_cast<uint32_t>(v);
    else if (k == "--cycles")
      cycles = static_cast<uint64_t>(v);
    else if (k == "--cpu")
      cpu = static_cast<int>(v);
    else if (k == "--priority")
      prio = static_cast<int>(v);
    else {
      std::fprintf(stderr, "unknown option %s\n", k.c_str());
      return 2;
    }
  }
  std::printf(
      "# cycle work per cycle (CycleWork on the simulated bus), period %u us, %llu cycles "
      "per point, SCHED_FIFO %d on CPU %d, wake-up thread %d same CPU, readers FIFO %d\n",
      period_us, static_cast<unsigned long long>(cycles), prio, cpu, prio - 1, prio - 10);
  std::printf(
      "| axes | readers asleep | work p50 µs | work p99 µs | work max µs | wake p99 µs | "
      "overruns | reader wake-ups (thread) |\n|---|---|---|---|---|---|---|---|\n");
  const uint32_t axis_counts[] = {1, 4, 16};
  const unsigned reader_counts[] = {0, 1, 16};
  Point grid[3][3];
  for (int a = 0; a < 3; ++a) {
    for (int r = 0; r < 3; ++r) {
      const Point p = run(axis_counts[a], reader_counts[r], period_us, cycles, cpu, prio);
      grid[a][r] = p;
      std::printf("| %u | %u | %.2f | %.2f | %.1f | %.1f | %llu | %llu |\n", axis_counts[a],
                  reader_counts[r], p.p50, p.p99, p.max, p.wake_p99,
                  static_cast<unsigned long long>(p.overruns),
                  static_cast<unsigned long long>(p.wake_calls));
      std::fflush(stdout);
    }
  }
  std::printf("# per-axis slope (1 -> 16 axes, no reader): p50 %.3f µs/axis, p99 %.3f µs/axis\n",
              (grid[2][0].p50 - grid[0][0].p50) / 15, (grid[2][0].p99 - grid[0][0].p99) / 15);
  for (int a = 0; a < 3; ++a)
    std::printf("# %u axes: 16 readers asleep over none: p50 %+.2f µs, p99 %+.2f µs\n",
                axis_counts[a], grid[a][2].p50 - grid[a][0].p50, grid[a][2].p99 - grid[a][0].p99);
  return 0;
}
