// What the CAN-I/O bus driver sustains on the timed virtual bus, next to the bus' bit-time bound:
//  1. shortest period: CanioBus (daemon side) and simulated CAN-I/O nodes (one module each) on
//     the timed virtual bus at 500 kbit/s and 1 Mbit/s, in virtual time (fake clock moved by
//     the bus: a receive that waits jumps to the next end of frame, where the nodes answer), so
//     every run is the same run and the figures are the bus', not this machine's scheduling.
//     For 1, 2, 4, 8 modules the shortest period (µs) with no overrun (the cycle's last input
//     object later than the next cycle's start) and no half sample in --cycles cycles, found by
//     bisection, beside the bit-time bound of the cycle (SYNC + 3 objects per module, worst-case
//     stuffing) and the ratio. The response timeout is the period (the driver's own default is
//     not what is measured here); the node's SYNC reaction delay is 0.
//  2. EnDat read-parameter latency in bus cycles through Flatstream at MTU 3, 4, 5 (stepped, fake
//     clock: cycles, not time), next to the lower bound of the MTU: the request's and the reply's
//     sequences, one per cycle each way.
//  3. (--realtime S) the verdict in real time, by the rule of bench/powerlink/run_cycle_bench.sh:
//     CanioBus on the cycle engine (SCHED_FIFO 80, CPU 1) against simulated nodes (a thread of
//     their own) on the timed virtual bus on the real clock, at the shortest whole period of at
//     least the worst-case bit-time bound / 0.9 (the bus ≥ 90 % loaded in the worst case), for 1,
//     4 and 8 modules, S seconds each; then cyclictest (same priority, CPU, period, duration).
//     Held: bus never down and no sample missing after the first 50 cycles ("resets"), and an
//     overrun share ≤ 1.1 × cyclictest's share of wake-ups later than period − work p50.
// Not part of ctest: build/bench/canio/canio_driver_bench [--cycles N] [--realtime S]
//   [--only-realtime].
#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "../../tests/canio_bus/rig.hpp"
#include "can/bit_budget.hpp"
#include "core/cycle_engine.hpp"
#include "endat/command.hpp"
#include "flatstream/channel.hpp"

using namespace ds1928;

namespace {

struct Sustained {
  uint64_t cycles = 0, overruns = 0, not_whole = 0;
  double load = 0.0;  // bus time of all frames / run time
  [[nodiscard]] bool ok() const { return overruns == 0 && not_whole == 0; }
};

Sustained run_period(int modules, uint32_t bitrate, uint32_t period_us, uint64_t cycles) {
  DaemonConfig c = test::canio_config(modules, period_us);
  c.canio.bitrate = bitrate;
  c.canio.response_timeout_us = period_us;
  test::Rig rig(c, true, true, test::BusMode::Timed);
  (void)rig.canio->start();
  Sustained s;
  const int64_t period_ns = int64_t{period_us} * 1000;
  for (uint64_t i = 0; i < cycles; ++i) {
    const int64_t start = test::Rig::kT0 + static_cast<int64_t>(i) * period_ns;
    (void)rig.cycle(i);
    if (test::fake_now() > start + period_ns) ++s.overruns;
    if (i < 10) continue;  // first cycles: the nodes' first answers
    for (const AxisIo& io : rig.io)
      if (!io.inputs_fresh) {
        ++s.not_whole;
        break;
      }
  }
  s.cycles = cycles;
  const canio::WireTotals wire = rig.bus->wire_totals();
  s.load = static_cast<double>(wire.busy_ns) /
           static_cast<double>(static_cast<int64_t>(cycles) * period_ns);
  return s;
}

// Cycles from submitting read-parameter until its reply is complete, at one MTU.
uint64_t read_param_cycles(uint8_t mtu) {
  DaemonConfig c = test::canio_config(1, 2000);
  c.axes[0].module.input_mtu = c.axes[0].module.output_mtu = mtu;
  test::Rig rig(c, true, true);
  (void)rig.canio->start();
  flatstream::MasterConfig fc;
  fc.input_mtu = fc.output_mtu = mtu;
  flatstream::MasterChannel channel(fc);
  const auto req =
      endat::encode_request(endat::Request::read(0xA1, 13), endat::CommandSet::EnDat22);
  uint64_t cycle = 0;
  // Let the channels synchronise first.
  for (; cycle < 20; ++cycle) {
    (void)rig.cycle(cycle);
    flatstream::apply(channel.step(flatstream::input_frame(rig.io[0].inputs), cycle * 2000),
                      rig.io[0].outputs);
  }
  (void)channel.submit(std::span<const uint8_t>(req->bytes.data(), req->size), 1);
  const uint64_t start = cycle;
  flatstream::Message m;
  for (; cycle < start + 2000; ++cycle) {
    (void)rig.cycle(cycle);
    flatstream::apply(channel.step(flatstream::input_frame(rig.io[0].inputs), cycle * 2000),
                      rig.io[0].outputs);
    if (channel.take_received(m)) return cycle - start + 1;
  }
  return 0;
}

// The cycle work of the real-time run: CanioBus's exchange, and what makes a cycle fail.
// Its own record of the work (wake-up to end of the exchange): on a 500 kbit/s bus 8 modules'
// exchange lasts longer than the engine's histogram range (4.096 ms).
struct RigTask final : CycleTask {
  RigTask(test::Rig& r, std::size_t capacity) : rig(r) { work_ns.reserve(capacity); }
  void run_cycle(const CycleContext& ctx) noexcept override {
    const ExchangeResult r = rig.canio->exchange(rig.io, ctx.start_ns, ctx.index);
    if (counting && work_ns.size() < work_ns.capacity())
      work_ns.push_back(test::Rig::monotonic() - ctx.woke_ns);
    if (++cycles <= kWarmup) return;
    if (!r.bus_up) ++down;
    for (const AxisIo& io : rig.io)
      if (!io.inputs_fresh) {
        ++not_whole;
        break;
      }
  }
  [[nodiscard]] double work_us(double q) const {
    if (work_ns.empty()) return 0.0;
    std::vector<int64_t> v(work_ns);
    std::sort(v.begin(), v.end());
    return static_cast<double>(v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))]) /
           1000.0;
  }
  static constexpr uint64_t kWarmup = 50;
  test::Rig& rig;
  bool counting = false;
  std::vector<int64_t> work_ns;
  uint64_t cycles = 0, down = 0, not_whole = 0;
};

// Share of cyclictest's wake-ups later than `slack_us` (same priority, CPU, period, duration).
double cyclictest_late_share(uint32_t period_us, uint32_t slack_us, int seconds, int prio, int cpu,
                             uint64_t& late, uint64_t& total) {
  const std::string cmd = "cyclictest -m -q -p " + std::to_string(prio) + " -a " +
                          std::to_string(cpu) + " -t 1 -i " + std::to_string(period_us) + " -l " +
                          std::to_string(uint64_t{1'000'000} * seconds / period_us) + " -h " +
                          std::to_string(period_us) + " 2>/dev/null";
  FILE* p = popen(cmd.c_str(), "r");
  late = total = 0;
  if (p == nullptr) return -1.0;
  char line[256];
  while (std::fgets(line, sizeof(line), p) != nullptr) {
    unsigned long lat = 0, n = 0;
    if (std::sscanf(line, "%lu %lu", &lat, &n) == 2 && line[0] != '#') {
      total += n;
      if (lat > slack_us) late += n;
    } else if (std::sscanf(line, "# Histogram Overflows: %lu", &n) == 1) {
      total += n;
      late += n;
    }
  }
  pclose(p);
  return total > 0 ? static_cast<double>(late) / static_cast<double>(total) : -1.0;
}

void realtime_verdicts(int seconds) {
  constexpr int kPrio = 80, kCpu = 1;
  std::printf(
      "Real time on the timed virtual bus, 500 kbit/s, period = worst-case bit-time bound / 0.9 "
      "(rounded down to 10 µs), %d s per point, then cyclictest (SCHED_FIFO %d, CPU %d, same "
      "period and duration):\n",
      seconds, kPrio, kCpu);
  std::printf(
      "| modules | bound worst µs | period µs | load (worst) | held | resets (down / missing) | "
      "overruns (share) | late ct (share) | ratio | work p50/p99 µs | wake p99 µs |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (int modules : {1, 4, 8}) {
    canio::CycleLoad load;
    load.modules = static_cast<uint32_t>(modules);
    load.sync = true;
    load.bitrate = 500'000;
    const auto bound = canio::cycle_budget(load);
    const auto bound_us = static_cast<uint32_t>(bound.time_worst_case_ns / 1000);
    const uint32_t period_us = bound_us * 10 / 9 / 10 * 10;  // bound/period ≥ 90 %
    DaemonConfig c = test::canio_config(modules, period_us);
    c.canio.bitrate = 500'000;
    c.cycle.rt_priority = kPrio;
    c.cycle.cpu = kCpu;
    test::Rig rig(c, false, true, test::BusMode::Timed);
    // The simulated nodes like ds1928-sim in the POWERLINK bench: SCHED_FIFO 70 on CPU 0.
    {
      sched_param sp{};
      sp.sched_priority = 70;
      pthread_setschedparam(rig.node_thread.native_handle(), SCHED_FIFO, &sp);
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(0, &set);
      pthread_setaffinity_np(rig.node_thread.native_handle(), sizeof(set), &set);
    }
    (void)rig.canio->start();
    const uint64_t cycles = uint64_t{1'000'000} * static_cast<uint64_t>(seconds) / period_us;
    RigTask task(rig, cycles);
    CycleEngine engine(c.cycle, task);
    (void)engine.run_cycles(RigTask::kWarmup);
    engine.request_stats_reset();
    task.counting = true;
    (void)engine.run_cycles(cycles);
    const CycleStatsSnapshot st = engine.stats_snapshot();
    const double work_p50 = task.work_us(0.5);
    const auto slack = static_cast<uint32_t>(std::max(0.0, period_us - work_p50));
    uint64_t late = 0, total = 0;
    const double ct = cyclictest_late_share(period_us, slack, seconds, kPrio, kCpu, late, total);
    const double share =
        st.cycles > 0 ? static_cast<double>(st.overruns) / static_cast<double>(st.cycles) : 1.0;
    const bool resets = task.down != 0 || task.not_whole != 0;
    const bool held =
        !resets && st.cycles > 0 && (st.overruns == 0 || (ct > 0 && share <= 1.1 * ct));
    char ratio[32];
    if (st.overruns == 0)
      std::snprintf(ratio, sizeof(ratio), "-");
    else if (ct > 0)
      std::snprintf(ratio, sizeof(ratio), "%.2f", share / ct);
    else
      std::snprintf(ratio, sizeof(ratio), "inf");
    std::printf(
        "| %d | %u | %u | %.0f %% | %s | %llu / %llu | %llu (%.3f %%) | %llu (%.3f %%) | %s | "
        "%.1f / %.1f | %.1f |\n",
        modules, bound_us, period_us,
        100.0 * static_cast<double>(bound_us) / static_cast<double>(period_us), held ? "yes" : "no",
        static_cast<unsigned long long>(task.down), static_cast<unsigned long long>(task.not_whole),
        static_cast<unsigned long long>(st.overruns), share * 100.0,
        static_cast<unsigned long long>(late), ct * 100.0, ratio, work_p50,
        static_cast<double>(st.work.p99_ns) / 1000.0,
        static_cast<double>(st.wake_latency.p99_ns) / 1000.0);
    std::fflush(stdout);
  }
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t cycles = 2000;
  int realtime_s = 0;
  bool only_realtime = false;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--cycles") == 0 && i + 1 < argc)
      cycles = std::stoull(argv[++i]);
    else if (std::strcmp(argv[i], "--realtime") == 0 && i + 1 < argc)
      realtime_s = std::atoi(argv[++i]);
    else if (std::strcmp(argv[i], "--only-realtime") == 0)
      only_realtime = true;
  }
  if (realtime_s > 0) realtime_verdicts(realtime_s);
  if (only_realtime) return 0;

  std::printf(
      "Shortest sustained period on the timed virtual bus (virtual time, %llu cycles, no overrun "
      "and no half sample), beside the bit-time bound (SYNC + 2 inputs + 1 output per module):\n",
      static_cast<unsigned long long>(cycles));
  std::printf(
      "| bit rate | modules | bound nominal µs | bound worst case µs | shortest period µs | ratio "
      "to worst case | bus load |\n|---|---|---|---|---|---|---|\n");
  for (uint32_t bitrate : {500'000u, 1'000'000u}) {
    for (int modules : {1, 2, 4, 8}) {
      canio::CycleLoad load;
      load.modules = static_cast<uint32_t>(modules);
      load.sync = true;
      load.bitrate = bitrate;
      const auto bound = canio::cycle_budget(load);
      // Bisection on µs: below the nominal bound nothing can hold; twice the worst case must.
      auto lo = static_cast<uint32_t>(bound.time_nominal_ns / 1000 / 2);
      auto hi = static_cast<uint32_t>(2 * bound.time_worst_case_ns / 1000);
      if (!run_period(modules, bitrate, hi, cycles).ok()) {
        std::printf("| %u | %d | not sustained at %u µs |\n", bitrate, modules, hi);
        continue;
      }
      while (hi - lo > 1) {
        const uint32_t mid = lo + (hi - lo) / 2;
        (run_period(modules, bitrate, mid, cycles).ok() ? hi : lo) = mid;
      }
      const Sustained s = run_period(modules, bitrate, hi, cycles);
      std::printf("| %s | %d | %lld | %lld | %u | %.3f | %.1f %% |\n",
                  bitrate == 500'000 ? "500 kbit/s" : "1 Mbit/s", modules,
                  static_cast<long long>(bound.time_nominal_ns / 1000),
                  static_cast<long long>(bound.time_worst_case_ns / 1000), hi,
                  static_cast<double>(hi) * 1000.0 / static_cast<double>(bound.time_worst_case_ns),
                  s.load * 100.0);
    }
  }
  std::printf("\n");
  // Request 3 bytes (04 MRS P), reply 5 bytes (04 MRS P VL VH); at MTU m one sequence carries
  // m − 1 bytes (the control byte takes one), so the bound is ceil(3/(m−1)) + ceil(5/(m−1))
  // cycles plus one cycle for the module to answer.
  std::printf("| MTU | read-param cycles | bound |\n|---|---|---|\n");
  for (uint8_t mtu : {uint8_t{3}, uint8_t{4}, uint8_t{5}}) {
    const unsigned per = mtu - 1u;
    const unsigned bound = (3 + per - 1) / per + (5 + per - 1) / per + 1;
    std::printf("| %u | %llu | %u |\n", mtu,
                static_cast<unsigned long long>(read_param_cycles(mtu)), bound);
  }
  return 0;
}
