#include "doctor.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

namespace ds1928::ctl {
namespace {

namespace fs = std::filesystem;

std::string path_in(const DoctorInput& in, const std::string& p) {
  std::string root = in.root;
  while (!root.empty() && root.back() == '/') root.pop_back();
  return root + p;
}

std::optional<std::string> read_text(const std::string& path) {
  std::ifstream f(path);
  if (!f) return std::nullopt;
  std::stringstream s;
  s << f.rdbuf();
  std::string t = s.str();
  while (!t.empty() && (t.back() == '\n' || t.back() == ' ')) t.pop_back();
  return t;
}

std::optional<std::string> read_in(const DoctorInput& in, const std::string& p) {
  return read_text(path_in(in, p));
}

Check pass(std::string name, std::string detail) {
  return {std::move(name), Verdict::Pass, std::move(detail), {}};
}
Check warn(std::string name, std::string detail, std::string fix) {
  return {std::move(name), Verdict::Warn, std::move(detail), std::move(fix)};
}
Check fail(std::string name, std::string detail, std::string fix) {
  return {std::move(name), Verdict::Fail, std::move(detail), std::move(fix)};
}

// The value of KEY=VALUE on the kernel command line ("" when absent; "1" for a bare KEY).
std::optional<std::string> cmdline_param(const std::string& cmdline, const std::string& key) {
  std::istringstream words(cmdline);
  std::string w;
  std::optional<std::string> found;
  while (words >> w) {
    if (w == key)
      found = "";
    else if (w.rfind(key + "=", 0) == 0)
      found = w.substr(key.size() + 1);
  }
  return found;
}

bool contains(const std::vector<int>& v, int x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

int cycle_cpu(const DoctorInput& in) {
  return in.config.cycle.cpu;
}

std::string cpu_dir(const DoctorInput& in) {
  return fmt::format("/sys/devices/system/cpu/cpu{}", std::max(cycle_cpu(in), 0));
}

// The unit file: [Service] KEY=VALUE lines (the last one wins).
std::optional<std::string> unit_value(const std::string& text, const std::string& key) {
  std::istringstream lines(text);
  std::string line;
  std::optional<std::string> v;
  while (std::getline(lines, line)) {
    if (line.rfind(key + "=", 0) == 0) v = line.substr(key.size() + 1);
  }
  return v;
}

bool interface_exists(const DoctorInput& in, const std::string& ifname) {
  std::error_code ec;
  return fs::exists(path_in(in, "/sys/class/net/" + ifname), ec);
}

}  // namespace

const char* to_string(Verdict v) noexcept {
  switch (v) {
    case Verdict::Pass:
      return "PASS";
    case Verdict::Warn:
      return "WARN";
    case Verdict::Fail:
      return "FAIL";
  }
  return "?";
}

std::vector<int> parse_cpu_list(const std::string& text) {
  std::vector<int> out;
  std::string t = text;
  // isolcpus may start with flags: "managed_irq,domain,1-3".
  std::istringstream parts(t);
  std::string part;
  while (std::getline(parts, part, ',')) {
    if (part.empty()) continue;
    if (!std::isdigit(static_cast<unsigned char>(part[0]))) continue;  // a flag
    const auto dash = part.find('-');
    char* end = nullptr;
    const long a = std::strtol(part.c_str(), &end, 10);
    long b = a;
    if (dash != std::string::npos) b = std::strtol(part.c_str() + dash + 1, &end, 10);
    if (a < 0 || b < a || b > 4096) return {};
    for (long c = a; c <= b; ++c) out.push_back(static_cast<int>(c));
  }
  return out;
}

std::string bus_interface(const DaemonConfig& c) {
  if (c.bus == BusKind::Powerlink) return c.powerlink.interface;
  if (c.bus == BusKind::Canio && c.canio.virtual_bus.empty()) return c.canio.interface;
  return {};
}

Check check_preemption(const DoctorInput& in) {
  if (read_in(in, "/sys/kernel/realtime").value_or("") == "1")
    return pass("preemption", "PREEMPT_RT kernel (/sys/kernel/realtime = 1)");
  const std::string version = read_in(in, "/proc/sys/kernel/version").value_or("");
  // A PREEMPT_DYNAMIC kernel says its current model in /sys/kernel/debug/sched/preempt.
  const std::string dynamic = read_in(in, "/sys/kernel/debug/sched/preempt").value_or("");
  if (version.find("PREEMPT_RT") != std::string::npos)
    return pass("preemption", "PREEMPT_RT kernel (" + version + ")");
  const std::string fix = "install a PREEMPT_RT kernel (Debian: apt install linux-image-rt-amd64)";
  if (dynamic.find("(full)") != std::string::npos)
    return warn("preemption", "PREEMPT_DYNAMIC, full preemption, not PREEMPT_RT (" + version + ")",
                fix);
  if (version.find("PREEMPT") != std::string::npos)
    return warn("preemption",
                "not PREEMPT_RT (" + version + (dynamic.empty() ? "" : "; model " + dynamic) +
                    "): wake-up latency of hundreds of µs under load",
                fix);
  return fail("preemption", "no kernel preemption (" + version + ")", fix);
}

Check check_governor(const DoctorInput& in) {
  const int cpu = std::max(cycle_cpu(in), 0);
  const auto gov = read_in(in, cpu_dir(in) + "/cpufreq/scaling_governor");
  if (!gov)
    return pass("governor",
                fmt::format("CPU {}: no cpufreq (fixed frequency or a virtual machine)", cpu));
  if (*gov == "performance") return pass("governor", fmt::format("CPU {}: performance", cpu));
  return warn(
      "governor",
      fmt::format("CPU {}: {} (the frequency follows the load: slower wake-ups)", cpu, *gov),
      fmt::format("cpupower -c {} frequency-set -g performance", cpu));
}

Check check_idle_states(const DoctorInput& in) {
  const int cpu = std::max(cycle_cpu(in), 0);
  const std::string dir = path_in(in, cpu_dir(in) + "/cpuidle");
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return pass("idle_states", fmt::format("CPU {}: no cpuidle states", cpu));
  std::vector<std::string> deep;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string n = e.path().filename().string();
    if (n.rfind("state", 0) != 0) continue;
    const long latency =
        std::strtol(read_text(e.path() / "latency").value_or("0").c_str(), nullptr, 10);
    const bool disabled = read_text(e.path() / "disable").value_or("0") == "1";
    if (!disabled && latency > 10)
      deep.push_back(fmt::format("{} ({} µs)", read_text(e.path() / "name").value_or(n), latency));
  }
  std::sort(deep.begin(), deep.end());
  if (deep.empty())
    return pass("idle_states", fmt::format("CPU {}: no enabled idle state deeper than 10 µs", cpu));
  std::string list;
  for (const auto& d : deep) list += (list.empty() ? "" : ", ") + d;
  if (in.config.cycle.hold_cpu_dma_latency)
    return pass("idle_states",
                fmt::format("CPU {}: {} enabled; the daemon holds /dev/cpu_dma_latency at 0 "
                            "(cycle.hold_cpu_dma_latency), which keeps them unused",
                            cpu, list));
  return warn("idle_states",
              fmt::format("CPU {}: {} enabled and cycle.hold_cpu_dma_latency off", cpu, list),
              "set cycle.hold_cpu_dma_latency: true, or boot with processor.max_cstate=1 "
              "intel_idle.max_cstate=0");
}

Check check_isolation(const DoctorInput& in) {
  const int cpu = cycle_cpu(in);
  if (cpu < 0)
    return warn("isolation",
                "cycle.cpu is -1: the cycle thread may run on any CPU, next to everything else",
                "set cycle.cpu to a CPU isolated with isolcpus= nohz_full= rcu_nocbs=");
  const std::string cmdline = read_in(in, "/proc/cmdline").value_or("");
  std::vector<std::string> missing, have;
  for (const char* key : {"isolcpus", "nohz_full", "rcu_nocbs"}) {
    const auto v = cmdline_param(cmdline, key);
    if (v && contains(parse_cpu_list(*v), cpu))
      have.push_back(key);
    else
      missing.push_back(key);
  }
  if (missing.empty())
    return pass("isolation", fmt::format("CPU {} in isolcpus, nohz_full and rcu_nocbs", cpu));
  std::string m, fix;
  for (const auto& k : missing) {
    m += (m.empty() ? "" : ", ") + k;
    fix += (fix.empty() ? "" : " ") + k + "=" + std::to_string(cpu);
  }
  return warn("isolation",
              fmt::format("CPU {} (cycle.cpu) not in {} of the kernel command line", cpu, m),
              "add " + fix + " to GRUB_CMDLINE_LINUX in /etc/default/grub, update-grub, reboot");
}

Check check_rt_throttling(const DoctorInput& in) {
  const auto runtime = read_in(in, "/proc/sys/kernel/sched_rt_runtime_us");
  if (!runtime) return warn("rt_throttling", "/proc/sys/kernel/sched_rt_runtime_us unreadable", "");
  if (*runtime == "-1") return pass("rt_throttling", "off (sched_rt_runtime_us = -1)");
  const auto period = read_in(in, "/proc/sys/kernel/sched_rt_period_us").value_or("1000000");
  return warn("rt_throttling",
              fmt::format("on: real-time tasks may use {} of every {} µs; a busy SCHED_FIFO thread "
                          "is stopped for the rest",
                          *runtime, period),
              "sysctl -w kernel.sched_rt_runtime_us=-1 (and in /etc/sysctl.d/)");
}

Check check_irq_affinity(const DoctorInput& in) {
  const std::string ifname = bus_interface(in.config);
  if (ifname.empty()) return pass("irq_affinity", "no bus interface (simulated or virtual bus)");
  const int cpu = cycle_cpu(in);
  std::error_code ec;
  // The daemon refuses to start on an interface that does not exist: a FAIL, not a hint.
  if (!interface_exists(in, ifname))
    return fail("irq_affinity",
                ifname + ": no such interface on this machine (ds1928d would refuse to start)",
                fmt::format("set {} to one of the interfaces `ip -br link` lists",
                            in.config.bus == BusKind::Powerlink ? "powerlink.interface"
                                                                : "canio.interface"));
  // MSI(-X) vectors of the device, else lines of /proc/interrupts that name the interface.
  std::vector<int> irqs;
  const std::string msi = path_in(in, "/sys/class/net/" + ifname + "/device/msi_irqs");
  if (fs::is_directory(msi, ec))
    for (const auto& e : fs::directory_iterator(msi, ec))
      irqs.push_back(std::atoi(e.path().filename().c_str()));
  if (irqs.empty()) {
    std::istringstream lines(read_in(in, "/proc/interrupts").value_or(""));
    std::string line;
    while (std::getline(lines, line)) {
      if (line.find(ifname) == std::string::npos) continue;
      irqs.push_back(std::atoi(line.c_str()));
    }
  }
  std::sort(irqs.begin(), irqs.end());
  if (irqs.empty())
    return pass("irq_affinity", ifname + ": no hardware interrupt (a virtual interface)");
  if (cpu < 0)
    return warn("irq_affinity",
                fmt::format("{}: {} interrupt(s); cycle.cpu is -1", ifname, irqs.size()),
                "set cycle.cpu, then put the interrupts on it");
  std::vector<int> elsewhere;
  for (int irq : irqs) {
    const auto list = read_in(in, fmt::format("/proc/irq/{}/smp_affinity_list", irq));
    if (!list || !contains(parse_cpu_list(*list), cpu)) elsewhere.push_back(irq);
  }
  if (elsewhere.empty())
    return pass("irq_affinity", fmt::format("{}: interrupt(s) {} served on CPU {}", ifname,
                                            fmt::join(irqs, ","), cpu));
  return warn("irq_affinity",
              fmt::format("{}: interrupt(s) {} not allowed on CPU {} (cycle.cpu): each frame wakes "
                          "the cycle thread from another CPU",
                          ifname, fmt::join(elsewhere, ","), cpu),
              fmt::format("for i in {}; do echo {} > /proc/irq/$i/smp_affinity_list; done (and "
                          "stop irqbalance from moving them)",
                          fmt::join(elsewhere, " "), cpu));
}

std::vector<Check> check_nic(const DoctorInput& in) {
  std::vector<Check> out;
  if (in.config.bus != BusKind::Powerlink || in.config.powerlink.interface.empty()) return out;
  const std::string ifname = in.config.powerlink.interface;
  // No such interface: irq_affinity FAILs naming it; ethtool has nothing to say about it.
  if (!interface_exists(in, ifname)) return out;
  const auto coal = in.run ? in.run("ethtool -c " + ifname) : std::nullopt;
  if (!coal) {
    out.push_back(warn("coalescing",
                       ifname + ": ethtool -c failed (ethtool missing, or the driver does not say)",
                       "apt install ethtool"));
  } else {
    long rx_usecs = -1, rx_frames = -1;
    std::istringstream lines(*coal);
    std::string line;
    while (std::getline(lines, line)) {
      if (line.rfind("rx-usecs:", 0) == 0) rx_usecs = std::strtol(line.c_str() + 9, nullptr, 10);
      if (line.rfind("rx-frames:", 0) == 0) rx_frames = std::strtol(line.c_str() + 10, nullptr, 10);
    }
    if (rx_usecs > 0)
      out.push_back(warn("coalescing",
                         fmt::format("{}: rx-usecs {}: each PRes waits up to {} µs in the NIC",
                                     ifname, rx_usecs, rx_usecs),
                         fmt::format("ethtool -C {} rx-usecs 0 rx-frames 1", ifname)));
    else
      out.push_back(
          pass("coalescing",
               fmt::format("{}: rx-usecs {}{}", ifname,
                           rx_usecs < 0 ? std::string("n/a") : std::to_string(rx_usecs),
                           rx_frames > 1 ? fmt::format(", rx-frames {}", rx_frames) : "")));
  }
  const auto eee = in.run ? in.run("ethtool --show-eee " + ifname) : std::nullopt;
  if (!eee) {
    out.push_back(pass("eee", ifname + ": no EEE support reported (ethtool --show-eee)"));
  } else if (eee->find("enabled - active") != std::string::npos ||
             eee->find("EEE status: enabled") != std::string::npos) {
    out.push_back(warn("eee",
                       ifname + ": Energy-Efficient Ethernet on: the link sleeps between frames",
                       fmt::format("ethtool --set-eee {} eee off", ifname)));
  } else {
    out.push_back(pass("eee", ifname + ": EEE off"));
  }
  return out;
}

std::vector<Check> check_can(const DoctorInput& in) {
  std::vector<Check> out;
  if (in.config.bus != BusKind::Canio || !in.config.canio.virtual_bus.empty()) return out;
  const std::string ifname = in.config.canio.interface;
  const auto text = in.run ? in.run("ip -details -json link show " + ifname) : std::nullopt;
  nlohmann::json link;
  if (text) {
    try {
      const auto j = nlohmann::json::parse(*text);
      if (j.is_array() && !j.empty()) link = j[0];
    } catch (const std::exception&) {
    }
  }
  const nlohmann::json info = link.is_object() && link.contains("linkinfo")
                                  ? link["linkinfo"].value("info_data", nlohmann::json::object())
                                  : nlohmann::json::object();
  if (!link.is_object()) {
    out.push_back(
        fail("can_bitrate", ifname + ": no such interface (ip -details link show)",
             fmt::format("ip link set {} type can bitrate {} restart-ms 100 && ip link set {} up",
                         ifname, in.config.canio.bitrate, ifname)));
    return out;
  }
  const uint32_t bitrate = info.contains("bittiming") ? info["bittiming"].value("bitrate", 0u) : 0u;
  if (bitrate == in.config.canio.bitrate)
    out.push_back(pass("can_bitrate", fmt::format("{}: {} bit/s as configured", ifname, bitrate)));
  else
    out.push_back(fail(
        "can_bitrate",
        fmt::format("{}: {} bit/s, canio.bitrate is {}", ifname, bitrate, in.config.canio.bitrate),
        fmt::format(
            "ip link set {} down && ip link set {} type can bitrate {} && ip link set {} up",
            ifname, ifname, in.config.canio.bitrate, ifname)));
  const uint32_t restart = info.value("restart_ms", 0u);
  if (restart > 0)
    out.push_back(pass("can_restart_ms", fmt::format("{}: restart-ms {}", ifname, restart)));
  else
    out.push_back(warn(
        "can_restart_ms",
        ifname + ": restart-ms 0: after a bus-off the controller stays off until restarted by hand",
        fmt::format("ip link set {} type can restart-ms 100", ifname)));
  const uint32_t txq = link.value("txqlen", 0u);
  if (txq >= 100)
    out.push_back(pass("can_txqueuelen", fmt::format("{}: txqueuelen {}", ifname, txq)));
  else
    out.push_back(
        warn("can_txqueuelen",
             fmt::format("{}: txqueuelen {}: the cycle's frames and SDO share it (ENOBUFS)", ifname,
                         txq),
             fmt::format("ip link set {} txqueuelen 100", ifname)));
  return out;
}

std::vector<Check> check_unit(const DoctorInput& in) {
  std::vector<Check> out;
  std::string unit = in.unit;
  if (unit.empty()) {
    for (const char* p :
         {"/etc/systemd/system/ds1928d.service", "/lib/systemd/system/ds1928d.service",
          "/usr/lib/systemd/system/ds1928d.service"}) {
      if (fs::exists(path_in(in, p))) {
        unit = p;
        break;
      }
    }
  }
  const auto text = unit.empty() ? std::nullopt : read_in(in, unit);
  if (!text) {
    // Without the unit: the limits this shell's processes get (ds1928d started by hand).
    rlimit mem{}, prio{};
    ::getrlimit(RLIMIT_MEMLOCK, &mem);
    ::getrlimit(RLIMIT_RTPRIO, &prio);
    const bool root = ::geteuid() == 0;
    const bool mem_ok = root || mem.rlim_cur == RLIM_INFINITY;
    const bool prio_ok = root || prio.rlim_cur >= static_cast<rlim_t>(in.config.cycle.rt_priority);
    const std::string d = fmt::format(
        "no ds1928d.service below {}: limits of this shell: RLIMIT_MEMLOCK {}, RLIMIT_RTPRIO {}{}",
        in.root,
        mem.rlim_cur == RLIM_INFINITY ? std::string("unlimited") : std::to_string(mem.rlim_cur),
        prio.rlim_cur == RLIM_INFINITY ? std::string("unlimited") : std::to_string(prio.rlim_cur),
        root ? " (root: not binding)" : "");
    out.push_back(
        mem_ok && prio_ok
            ? pass("limits", d)
            : warn("limits", d,
                   "LimitMEMLOCK=infinity and LimitRTPRIO=99 in the unit, or "
                   "@ds1928d - memlock unlimited / rtprio 99 in /etc/security/limits.d/"));
    return out;
  }
  const std::string mem = unit_value(*text, "LimitMEMLOCK").value_or("");
  const std::string prio = unit_value(*text, "LimitRTPRIO").value_or("");
  const bool mem_ok = mem == "infinity" || (in.config.cycle.lock_memory == false);
  const bool prio_ok = !prio.empty() && std::atoi(prio.c_str()) >= in.config.cycle.rt_priority;
  const std::string d = fmt::format("{}: LimitMEMLOCK={} LimitRTPRIO={} (cycle.rt_priority {})",
                                    unit, mem.empty() ? "unset" : mem,
                                    prio.empty() ? "unset" : prio, in.config.cycle.rt_priority);
  if (mem_ok && prio_ok)
    out.push_back(pass("limits", d));
  else
    out.push_back(
        fail("limits", d,
             fmt::format("systemctl edit ds1928d: [Service] LimitMEMLOCK=infinity LimitRTPRIO={}",
                         std::max(in.config.cycle.rt_priority, 1))));
  const auto aff = unit_value(*text, "CPUAffinity");
  const int cpu = cycle_cpu(in);
  if (!aff || aff->empty()) {
    out.push_back(pass("cpu_affinity",
                       unit + ": no CPUAffinity= (the cycle thread pins itself to cycle.cpu)"));
  } else {
    std::string list = *aff;
    std::replace(list.begin(), list.end(), ' ', ',');
    const auto cpus = parse_cpu_list(list);
    if (cpu < 0 || contains(cpus, cpu))
      out.push_back(pass("cpu_affinity",
                         fmt::format("{}: CPUAffinity={} includes cycle.cpu {}", unit, *aff, cpu)));
    else
      out.push_back(fail(
          "cpu_affinity",
          fmt::format("{}: CPUAffinity={} excludes cycle.cpu {}: the cycle thread cannot be pinned",
                      unit, *aff, cpu),
          fmt::format("systemctl edit ds1928d: [Service] CPUAffinity={} (or drop it)", cpu)));
  }
  return out;
}

Check check_measured_cycles(const MeasuredCycles& m) {
  const char* name = "measured_wakeup";
  if (m.cycles == 0)
    return fail(name, fmt::format("the cycle engine ran no cycle in {:.1f} s", m.seconds),
                "see the rt_status of --measure; run as root or with CAP_SYS_NICE");
  const double max_us = static_cast<double>(m.wake_max_ns) / 1000.0;
  const double p99_us = static_cast<double>(m.wake_p99_ns) / 1000.0;
  const std::string figures =
      fmt::format("{} cycles at {} µs: wake-up p99 {:.1f} µs, max {:.1f} µs, {} overrun(s)",
                  m.cycles, m.period_us, p99_us, max_us, m.overruns);
  if (m.wake_max_ns < static_cast<int64_t>(m.period_us) * 1000 && m.overruns == 0)
    return pass(name, figures + ": every cycle started within its period");
  // At SCHED_FIFO the machine's ordinary load does not outrank the cycle thread: what stops it
  // for a period or more is below the scheduler (a VM's host not running the vCPU, SMIs) or the
  // kernel's own work on that CPU.
  return warn(name,
              figures +
                  ": a cycle started a period or more late, and a CN misses that cycle's SoC "
                  "(a VM's host not running the vCPU, SMIs, or kernel work on the CPU)",
              "on a VM: dedicated, pinned vCPUs on a host with CPUs to spare (or bare metal); "
              "else isolate cycle.cpu (see isolation) and look for SMIs with hwlatdetect "
              "(rt-tests)");
}

std::vector<Check> run_doctor(const DoctorInput& in) {
  std::vector<Check> out{check_preemption(in), check_governor(in),      check_idle_states(in),
                         check_isolation(in),  check_rt_throttling(in), check_irq_affinity(in)};
  for (auto* f : {&check_nic, &check_can, &check_unit})
    for (Check& c : (*f)(in)) out.push_back(std::move(c));
  return out;
}

}  // namespace ds1928::ctl
