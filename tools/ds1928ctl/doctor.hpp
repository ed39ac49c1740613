// `ds1928ctl doctor` (docs/operations.md "Pre-flight check"): the real-time settings of the
// machine against the daemon's configuration, one verdict per check with the one-line fix. Every
// file is read below `root` (tests: a fake /proc and /sys); the two commands it runs (ethtool,
// ip) are given, so a test can put fakes in their place.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "config/config.hpp"

namespace ds1928::ctl {

enum class Verdict { Pass, Warn, Fail };
[[nodiscard]] const char* to_string(Verdict v) noexcept;

struct Check {
  std::string name;  // "preemption", "governor", ...
  Verdict verdict = Verdict::Pass;
  std::string detail;  // what was found
  std::string fix;     // the one-line fix ("" on PASS)
};

struct DoctorInput {
  std::string root = "/";  // prefix of every /proc, /sys and unit file path
  DaemonConfig config;
  // The unit's file below root; "" : the first of /etc/systemd/system/ds1928d.service,
  // /lib/systemd/system/ds1928d.service, /usr/lib/systemd/system/ds1928d.service.
  std::string unit;
  // Runs a command line, returns its standard output; nullopt when it could not run / failed.
  std::function<std::optional<std::string>(const std::string&)> run;
};

// The interface the bus uses ("" when none: simulated bus, virtual CAN bus).
[[nodiscard]] std::string bus_interface(const DaemonConfig& c);

// One function per check (unit tests call them one by one); run_doctor() runs them all.
[[nodiscard]] Check check_preemption(const DoctorInput& in);
[[nodiscard]] Check check_governor(const DoctorInput& in);
[[nodiscard]] Check check_idle_states(const DoctorInput& in);
[[nodiscard]] Check check_isolation(const DoctorInput& in);
[[nodiscard]] Check check_rt_throttling(const DoctorInput& in);
[[nodiscard]] Check check_irq_affinity(const DoctorInput& in);
[[nodiscard]] std::vector<Check> check_nic(const DoctorInput& in);  // coalescing, EEE
[[nodiscard]] std::vector<Check> check_can(
    const DoctorInput& in);  // bitrate, restart-ms, txqueuelen
[[nodiscard]] std::vector<Check> check_unit(const DoctorInput& in);  // limits, CPUAffinity
[[nodiscard]] std::vector<Check> run_doctor(const DoctorInput& in);

// What `--measure` saw of the daemon's cycle engine (no bus) at the configured period, priority
// and CPU, and its verdict ("measured_wakeup"): a wake-up later than the period is a cycle whose
// SoC a CN misses.
struct MeasuredCycles {
  double seconds = 0;
  uint32_t period_us = 0;
  uint64_t cycles = 0;
  uint64_t overruns = 0;
  int64_t wake_p99_ns = 0;
  int64_t wake_max_ns = 0;
};
[[nodiscard]] Check check_measured_cycles(const MeasuredCycles& m);

// Parses a CPU list ("1,3-5"); empty on a syntax error.
[[nodiscard]] std::vector<int> parse_cpu_list(const std::string& text);

}  // namespace ds1928::ctl
