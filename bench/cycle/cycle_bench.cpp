// Wake-up latency of the cycle engine next to cyclictest's, at the same interval, priority and
// CPU, in one run. Both distributions are binned the way cyclictest bins them (latency truncated
// to whole µs) and quantiles use the same rule (upper edge of the bin holding the quantile), so
// the columns compare like with like.
//
//   cycle_bench [--cycles N] [--priority P] [--cpu C] [--spin-us S] [--periods 200,100]
//               [--rounds R] [--cyclictest PATH | --no-cyclictest]
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/cycle_engine.hpp"

namespace {

using ds1928::CycleConfig;
using ds1928::CycleContext;
using ds1928::CycleEngine;
using ds1928::CycleTask;
using ds1928::LatencyHistogram;

// Latency distribution in 1 µs bins (cyclictest's resolution).
struct UsHistogram {
  std::vector<uint64_t> bins = std::vector<uint64_t>(LatencyHistogram::kRangeNs / 1000, 0);
  uint64_t overflow = 0;
  double max_us = 0;

  [[nodiscard]] uint64_t total() const {
    uint64_t t = overflow;
    for (auto b : bins) t += b;
    return t;
  }
  [[nodiscard]] double quantile(double q) const {
    const uint64_t n = total();
    if (n == 0) return 0;
    auto target = static_cast<uint64_t>(std::ceil(q * static_cast<double>(n)));
    target = std::clamp<uint64_t>(target, 1, n);
    uint64_t seen = 0;
    for (std::size_t i = 0; i < bins.size(); ++i) {
      seen += bins[i];
      if (seen >= target) return std::min(static_cast<double>(i + 1), max_us);
    }
    return max_us;
  }
  void merge(const UsHistogram& o) {
    for (std::size_t i = 0; i < bins.size(); ++i) bins[i] += o.bins[i];
    overflow += o.overflow;
    max_us = std::max(max_us, o.max_us);
  }
};

struct EmptyTask : CycleTask {
  void run_cycle(const CycleContext&) noexcept override {}
};

struct EngineRun {
  UsHistogram hist;
  std::string status;
  uint64_t overruns = 0;
  bool ok = false;
};

EngineRun run_engine(uint32_t period_us, uint32_t spin_us, int priority, int cpu, uint64_t cycles) {
  EngineRun run;
  CycleConfig config;
  config.period_us = period_us;
  config.rt_priority = priority;
  config.cpu = cpu;
  config.spin_us = spin_us;
  EmptyTask task;
  auto engine = std::make_unique<CycleEngine>(config, task);
  auto r = engine->run_cycles(cycles);
  run.status = engine->rt_status_text();
  if (r.error) {
    run.status = r.error.message();
    return run;
  }
  // 250 ns bins fold exactly into 1 µs bins (4 per µs).
  const auto& h = engine->stats().wake_latency();
  constexpr std::size_t kPerUs = 1000 / LatencyHistogram::kBinWidthNs;
  for (std::size_t i = 0; i < LatencyHistogram::kBins; ++i) run.hist.bins[i / kPerUs] += h.bin(i);
  run.hist.overflow = h.overflow();
  run.hist.max_us = static_cast<double>(h.max_ns() / 1000);  // truncated, like cyclictest
  run.overruns = engine->stats_snapshot().overruns;
  run.ok = true;
  return run;
}

std::optional<UsHistogram> run_cyclictest(const std::string& exe, uint32_t period_us, int priority,
                                          int cpu, uint64_t cycles, std::string& error) {
  std::ostringstream cmd;
  cmd << exe << " -m -p " << priority << " -i " << period_us << " -l " << cycles << " -q -h "
      << LatencyHistogram::kRangeNs / 1000;
  if (cpu >= 0) cmd << " -a " << cpu;
  cmd << " 2>&1";
  FILE* p = popen(cmd.str().c_str(), "r");
  if (p == nullptr) {
    error = "cannot run " + exe;
    return std::nullopt;
  }
  UsHistogram h;
  bool saw_histogram = false;
  char line[512];
  std::string unexpected;
  while (std::fgets(line, sizeof(line), p) != nullptr) {
    unsigned long bin = 0;
    unsigned long long count = 0;
    unsigned long long value = 0;
    if (std::sscanf(line, "%lu %llu", &bin, &count) == 2 && line[0] != '#') {
      if (bin < h.bins.size()) h.bins[bin] += count;
      saw_histogram = true;
    } else if (std::sscanf(line, "# Max Latencies: %llu", &value) == 1) {
      h.max_us = static_cast<double>(value);
    } else if (std::sscanf(line, "# Histogram Overflows: %llu", &value) == 1) {
      h.overflow = value;
    } else if (line[0] != '#' && unexpected.size() < 400) {
      unexpected += line;
    }
  }
  const int rc = pclose(p);
  if (rc != 0 || !saw_histogram) {
    error = cmd.str() + " failed (status " + std::to_string(rc) + "): " + unexpected;
    return std::nullopt;
  }
  return h;
}

void print_row(const char* name, const UsHistogram& h) {
  std::printf("  %-22s %8.0f %8.0f %8.0f %8.0f %9llu\n", name, h.quantile(0.5), h.quantile(0.99),
              h.quantile(0.999), h.max_us, static_cast<unsigned long long>(h.total()));
}
double ratio(double a, double b) {
  return b > 0 ? a / b : 0.0;
}
void print_ratio(const char* name, const UsHistogram& e, const UsHistogram& c) {
  std::printf("  %-22s %8.2f %8.2f %8.2f %8.2f\n", name, ratio(e.quantile(0.5), c.quantile(0.5)),
              ratio(e.quantile(0.99), c.quantile(0.99)),
              ratio(e.quantile(0.999), c.quantile(0.999)), ratio(e.max_us, c.max_us));
}

std::vector<uint32_t> parse_list(const char* s) {
  std::vector<uint32_t> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) out.push_back(static_cast<uint32_t>(std::stoul(item)));
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t cycles = 20000;
  int priority = 80;
  int cpu = std::thread::hardware_concurrency() > 1 ? 1 : 0;
  uint32_t spin_us = 50;
  int rounds = 1;
  std::vector<uint32_t> periods{200, 100};
  std::string cyclictest = "cyclictest";
  bool with_cyclictest = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--cycles")
      cycles = std::stoull(next());
    else if (a == "--priority")
      priority = std::stoi(next());
    else if (a == "--cpu")
      cpu = std::stoi(next());
    else if (a == "--spin-us")
      spin_us = static_cast<uint32_t>(std::stoul(next()));
    else if (a == "--periods")
      periods = parse_list(next());
    else if (a == "--rounds")
      rounds = std::max(1, std::stoi(next()));
    else if (a == "--cyclictest")
      cyclictest = next();
    else if (a == "--no-cyclictest")
      with_cyclictest = false;
    else {
      std::fprintf(stderr,
                   "usage: %s [--cycles N] [--priority P] [--cpu C] [--spin-us S] "
                   "[--periods 200,100] [--rounds R] [--cyclictest PATH | --no-cyclictest]\n",
                   argv[0]);
      return 2;
    }
  }

  std::printf(
      "cycle engine vs cyclictest: %llu cycles per run, %d round(s), SCHED_FIFO %d, CPU %d\n",
      static_cast<unsigned long long>(cycles), rounds, priority, cpu);
  std::printf(
      "wake-up latency in us (truncated to whole us as cyclictest does; quantile = upper "
      "edge of its 1 us bin)\n");
  bool goal_met = true;
  for (uint32_t period : periods) {
    UsHistogram ct, off, on;
    std::string status, ct_error;
    uint64_t overruns_off = 0, overruns_on = 0;
    bool have_ct = with_cyclictest;
    const uint32_t spin = std::min(spin_us, period / 2);
    // Interleaved so that a change in background load hits all three alike.
    for (int r = 0; r < rounds; ++r) {
      if (have_ct) {
        auto h = run_cyclictest(cyclictest, period, priority, cpu, cycles, ct_error);
        if (h)
          ct.merge(*h);
        else
          have_ct = false;
      }
      auto e_off = run_engine(period, 0, priority, cpu, cycles);
      auto e_on = run_engine(period, spin, priority, cpu, cycles);
      if (!e_off.ok || !e_on.ok) {
        std::fprintf(stderr, "engine failed: %s\n", e_off.status.c_str());
        return 1;
      }
      off.merge(e_off.hist);
      on.merge(e_on.hist);
      overruns_off += e_off.overruns;
      overruns_on += e_on.overruns;
      status = e_off.status;
    }
    std::printf("\nperiod %u us  (engine: %s)\n", period, status.c_str());
    std::printf("  %-22s %8s %8s %8s %8s %9s\n", "", "p50", "p99", "p99.9", "max", "samples");
    if (have_ct)
      print_row("cyclictest", ct);
    else
      std::printf("  cyclictest: not run (%s)\n", ct_error.empty() ? "disabled" : ct_error.c_str());
    print_row("engine, spin off", off);
    char spin_name[64];
    std::snprintf(spin_name, sizeof(spin_name), "engine, spin %u us", spin);
    print_row(spin_name, on);
    std::printf("  overruns: spin off %llu, spin on %llu\n",
                static_cast<unsigned long long>(overruns_off),
                static_cast<unsigned long long>(overruns_on));
    if (have_ct) {
      std::printf("  ratio engine/cyclictest\n");
      print_ratio("spin off", off, ct);
      print_ratio(spin_name, on, ct);
      const double r_off = ratio(off.quantile(0.99), ct.quantile(0.99));
      const bool off_ok = off.quantile(0.99) <= 1.1 * ct.quantile(0.99);
      const bool on_ok = on.quantile(0.99) < ct.quantile(0.99);
      std::printf("  goal spin off p99 <= 1.1 x cyclictest: %s (%.2f); spin on p99 lower: %s\n",
                  off_ok ? "met" : "NOT met", r_off, on_ok ? "met" : "NOT met");
      goal_met = goal_met && off_ok && on_ok;
    }
  }
  return goal_met ? 0 : 3;
}
