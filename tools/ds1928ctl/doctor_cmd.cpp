// `ds1928ctl doctor [--config FILE] [--root DIR] [--measure S] [--json]`: the pre-flight check
// (doctor.hpp), and with --measure the daemon's own cycle engine at the configured period,
// priority and CPU for S seconds without a bus, judged as one more check (measured_wakeup).
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <thread>

#include "commands.hpp"
#include "config/config_loader.hpp"
#include "core/cycle_engine.hpp"
#include "doctor.hpp"

namespace ds1928::ctl {
namespace {

using json = nlohmann::json;

struct DoctorArgs {
  std::string config = "/etc/ds1928d/ds1928d.yaml";
  std::string root = "/";
  std::string unit;
  double measure_s = 0;
};

std::optional<std::string> run_command(const std::string& cmd) {
  FILE* p = ::popen((cmd + " 2>/dev/null").c_str(), "r");
  if (p == nullptr) return std::nullopt;
  std::string out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int rc = ::pclose(p);
  if (rc != 0) return std::nullopt;
  return out;
}

struct NoWork final : CycleTask {
  void run_cycle(const CycleContext&) noexcept override {}
};

int run(const Context& ctx, const DoctorArgs& args) {
  const ConfigResult loaded = load_config(args.config);
  if (!loaded.ok()) {
    std::cerr << loaded.error_report();
    std::cerr << "ds1928ctl doctor: cannot check against " << args.config << " (use --config)\n";
    return kUsage;
  }
  DoctorInput in;
  in.root = args.root;
  in.config = loaded.config();
  in.unit = args.unit;
  in.run = run_command;
  std::vector<Check> checks = run_doctor(in);
  json j{{"config", args.config}, {"checks", json::array()}};
  if (args.measure_s > 0) {
    NoWork work;
    CycleConfig cc = in.config.cycle;
    CycleEngine engine(cc, work);
    const auto started = engine.start();
    if (!started) {
      std::cerr << "ds1928ctl doctor: cycle engine: " << started.error.message() << "\n";
      return kUsage;
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(args.measure_s));
    engine.stop();
    const auto s = engine.stats_snapshot();
    j["measure"] = {{"seconds", args.measure_s},
                    {"period_us", cc.period_us},
                    {"rt_priority", cc.rt_priority},
                    {"cpu", cc.cpu},
                    {"rt_status", engine.rt_status_text()},
                    {"cycles", s.cycles},
                    {"overruns", s.overruns},
                    {"wake_latency_ns",
                     {{"p50", s.wake_latency.p50_ns},
                      {"p99", s.wake_latency.p99_ns},
                      {"max", s.wake_latency.max_ns}}}};
    if (!ctx.json)
      // The engine's text names the priority, the CPU and whether it got them.
      std::printf(
          "measure  %.0f s at %u µs (%s): %llu cycles, %llu overruns, "
          "wake-up p50 %.1f µs, p99 %.1f µs, max %.1f µs\n",
          args.measure_s, cc.period_us, engine.rt_status_text().c_str(),
          static_cast<unsigned long long>(s.cycles), static_cast<unsigned long long>(s.overruns),
          s.wake_latency.p50_ns / 1000.0, s.wake_latency.p99_ns / 1000.0,
          s.wake_latency.max_ns / 1000.0);
    // The measurement's verdict is one more check: counted in the summary and the exit code.
    checks.push_back(check_measured_cycles({args.measure_s, cc.period_us, s.cycles, s.overruns,
                                            static_cast<int64_t>(s.wake_latency.p99_ns),
                                            static_cast<int64_t>(s.wake_latency.max_ns)}));
  }
  int fails = 0, warns = 0;
  for (const Check& c : checks) {
    fails += c.verdict == Verdict::Fail;
    warns += c.verdict == Verdict::Warn;
    j["checks"].push_back({{"name", c.name},
                           {"verdict", to_string(c.verdict)},
                           {"detail", c.detail},
                           {"fix", c.fix.empty() ? json(nullptr) : json(c.fix)}});
    if (!ctx.json) {
      std::printf("%s  %-15s %s\n", to_string(c.verdict), c.name.c_str(), c.detail.c_str());
      if (!c.fix.empty()) std::printf("      fix: %s\n", c.fix.c_str());
    }
  }
  j["summary"] = {{"pass", checks.size() - fails - warns}, {"warn", warns}, {"fail", fails}};
  if (ctx.json)
    std::cout << j.dump() << std::endl;
  else
    std::printf("%zu checks: %zu pass, %d warn, %d fail\n", checks.size(),
                checks.size() - fails - warns, warns, fails);
  return fails > 0 ? 1 : kOk;
}

}  // namespace

void add_doctor_command(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<DoctorArgs>();
  auto* doc = app.add_subcommand(
      "doctor",
      "Check the machine's real-time settings against the configuration (exit 1: a check failed)");
  doc->add_option("--config,-c", args->config,
                  "The daemon's configuration (default: the packaged /etc/ds1928d/ds1928d.yaml)")
      ->capture_default_str();
  doc->add_option("--root", args->root, "Read /proc, /sys and the unit below this directory")
      ->capture_default_str();
  doc->add_option("--unit", args->unit, "The unit file (below --root); default: the installed one");
  doc->add_option("--measure", args->measure_s,
                  "Run the cycle engine (no bus) at the configured period/priority/CPU for S s")
      ->check(CLI::Range(0.1, 3600.0));
  doc->callback([&ctx, args] { ctx.action = [&ctx, args] { return run(ctx, *args); }; });
}

}  // namespace ds1928::ctl
