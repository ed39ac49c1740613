// `ds1928ctl doctor`'s checks on fake /proc and /sys roots (and fake ethtool / ip output): each
// check's PASS and its WARN or FAIL, with the fix naming the cycle CPU or interface.
#include "doctor.hpp"

#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <map>

using namespace ds1928;
using namespace ds1928::ctl;
namespace fs = std::filesystem;

namespace {

struct FakeRoot {
  FakeRoot() {
    char tmpl[] = "/tmp/ds1928-doctor.XXXXXX";
    dir = ::mkdtemp(tmpl);
    in.root = dir;
    in.config.cycle.cpu = 1;
    in.config.cycle.rt_priority = 80;
    in.run = [this](const std::string& cmd) -> std::optional<std::string> {
      const auto it = commands.find(cmd);
      if (it == commands.end()) return std::nullopt;
      return it->second;
    };
  }
  ~FakeRoot() { fs::remove_all(dir); }
  void put(const std::string& path, const std::string& text) {
    fs::create_directories(fs::path(dir + path).parent_path());
    std::ofstream(dir + path) << text << "\n";
  }
  std::string dir;
  DoctorInput in;
  std::map<std::string, std::string> commands;
};

}  // namespace

TEST_CASE("doctor: preemption model", "[doctor]") {
  FakeRoot r;
  r.put("/proc/sys/kernel/version", "#1 SMP PREEMPT_DYNAMIC Debian 6.1.0");
  CHECK(check_preemption(r.in).verdict == Verdict::Warn);
  CHECK(check_preemption(r.in).fix.find("linux-image-rt") != std::string::npos);
  r.put("/proc/sys/kernel/version", "#1 SMP Debian 6.1.0");
  CHECK(check_preemption(r.in).verdict == Verdict::Fail);
  r.put("/sys/kernel/realtime", "1");
  CHECK(check_preemption(r.in).verdict == Verdict::Pass);
}

TEST_CASE("doctor: governor and idle states of the cycle CPU", "[doctor]") {
  FakeRoot r;
  CHECK(check_governor(r.in).verdict == Verdict::Pass);  // no cpufreq
  r.put("/sys/devices/system/cpu/cpu1/cpufreq/scaling_governor", "powersave");
  const Check g = check_governor(r.in);
  CHECK(g.verdict == Verdict::Warn);
  CHECK(g.fix == "cpupower -c 1 frequency-set -g performance");
  r.put("/sys/devices/system/cpu/cpu1/cpufreq/scaling_governor", "performance");
  CHECK(check_governor(r.in).verdict == Verdict::Pass);

  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state0/name", "POLL");
  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state0/latency", "0");
  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state0/disable", "0");
  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state2/name", "C6");
  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state2/latency", "133");
  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state2/disable", "0");
  r.in.config.cycle.hold_cpu_dma_latency = false;
  const Check i = check_idle_states(r.in);
  CHECK(i.verdict == Verdict::Warn);
  CHECK(i.detail.find("C6 (133 µs)") != std::string::npos);
  r.in.config.cycle.hold_cpu_dma_latency = true;  // the daemon holds cpu_dma_latency at 0
  CHECK(check_idle_states(r.in).verdict == Verdict::Pass);
  r.in.config.cycle.hold_cpu_dma_latency = false;
  r.put("/sys/devices/system/cpu/cpu1/cpuidle/state2/disable", "1");
  CHECK(check_idle_states(r.in).verdict == Verdict::Pass);
}

TEST_CASE("doctor: isolation against cycle.cpu", "[doctor]") {
  FakeRoot r;
  r.put("/proc/cmdline", "BOOT_IMAGE=/vmlinuz root=/dev/sda1 quiet");
  Check c = check_isolation(r.in);
  CHECK(c.verdict == Verdict::Warn);
  CHECK(c.fix.find("isolcpus=1 nohz_full=1 rcu_nocbs=1") != std::string::npos);
  r.put("/proc/cmdline",
        "root=/dev/sda1 isolcpus=managed_irq,domain,1-3 nohz_full=1-3 rcu_nocbs=2");
  c = check_isolation(r.in);
  CHECK(c.verdict == Verdict::Warn);
  CHECK(c.detail.find("rcu_nocbs") != std::string::npos);
  CHECK(c.detail.find("isolcpus") == std::string::npos);
  r.put("/proc/cmdline", "root=/dev/sda1 isolcpus=1 nohz_full=1 rcu_nocbs=1");
  CHECK(check_isolation(r.in).verdict == Verdict::Pass);
  r.in.config.cycle.cpu = -1;
  CHECK(check_isolation(r.in).verdict == Verdict::Warn);
  CHECK(parse_cpu_list("0,2-4") == std::vector<int>{0, 2, 3, 4});
  CHECK(parse_cpu_list("5-2").empty());
}

TEST_CASE("doctor: RT throttling", "[doctor]") {
  FakeRoot r;
  r.put("/proc/sys/kernel/sched_rt_runtime_us", "950000");
  r.put("/proc/sys/kernel/sched_rt_period_us", "1000000");
  CHECK(check_rt_throttling(r.in).verdict == Verdict::Warn);
  CHECK(check_rt_throttling(r.in).fix.find("sched_rt_runtime_us=-1") != std::string::npos);
  r.put("/proc/sys/kernel/sched_rt_runtime_us", "-1");
  CHECK(check_rt_throttling(r.in).verdict == Verdict::Pass);
}

TEST_CASE("doctor: IRQ affinity of the POWERLINK NIC against the cycle CPU", "[doctor]") {
  FakeRoot r;
  r.in.config.bus = BusKind::Powerlink;
  r.in.config.powerlink.interface = "eth1";
  // No such interface: start refuses it, so does the doctor (FAIL naming the key), and the
  // NIC checks have nothing to ask ethtool about.
  const Check missing = check_irq_affinity(r.in);
  CHECK(missing.verdict == Verdict::Fail);
  CHECK(missing.detail.find("eth1: no such interface") != std::string::npos);
  CHECK(missing.fix.find("powerlink.interface") != std::string::npos);
  CHECK(check_nic(r.in).empty());
  r.put("/sys/class/net/eth1/operstate", "up");
  // No hardware interrupt (veth): nothing to place.
  CHECK(check_irq_affinity(r.in).verdict == Verdict::Pass);
  r.put("/sys/class/net/eth1/device/msi_irqs/125", "msi");
  r.put("/sys/class/net/eth1/device/msi_irqs/126", "msi");
  r.put("/proc/irq/125/smp_affinity_list", "1");
  r.put("/proc/irq/126/smp_affinity_list", "0");
  Check c = check_irq_affinity(r.in);
  CHECK(c.verdict == Verdict::Warn);
  CHECK(c.detail.find("126") != std::string::npos);
  CHECK(c.detail.find("125") == std::string::npos);
  CHECK(c.fix.find("echo 1 > /proc/irq/$i/smp_affinity_list") != std::string::npos);
  r.put("/proc/irq/126/smp_affinity_list", "0-3");
  CHECK(check_irq_affinity(r.in).verdict == Verdict::Pass);
  // A CAN controller found by name in /proc/interrupts.
  FakeRoot can;
  can.in.config.bus = BusKind::Canio;
  can.in.config.canio.interface = "can0";
  can.put("/sys/class/net/can0/operstate", "up");
  can.put("/proc/interrupts",
          "           CPU0       CPU1\n  42:      12     0   IO-APIC   42-fasteoi   can0\n");
  can.put("/proc/irq/42/smp_affinity_list", "0");
  CHECK(check_irq_affinity(can.in).verdict == Verdict::Warn);
}

TEST_CASE("doctor: NIC coalescing and EEE from ethtool", "[doctor]") {
  FakeRoot r;
  r.in.config.bus = BusKind::Powerlink;
  r.in.config.powerlink.interface = "eth1";
  r.put("/sys/class/net/eth1/operstate", "up");
  r.commands["ethtool -c eth1"] = "Coalesce parameters for eth1:\nrx-usecs: 50\nrx-frames: 0\n";
  r.commands["ethtool --show-eee eth1"] =
      "EEE settings for eth1:\n\tEEE status: enabled - active\n";
  auto checks = check_nic(r.in);
  REQUIRE(checks.size() == 2);
  CHECK(checks[0].verdict == Verdict::Warn);
  CHECK(checks[0].fix == "ethtool -C eth1 rx-usecs 0 rx-frames 1");
  CHECK(checks[1].verdict == Verdict::Warn);
  CHECK(checks[1].fix == "ethtool --set-eee eth1 eee off");
  r.commands["ethtool -c eth1"] = "rx-usecs: 0\n";
  r.commands["ethtool --show-eee eth1"] = "\tEEE status: disabled\n";
  checks = check_nic(r.in);
  CHECK(checks[0].verdict == Verdict::Pass);
  CHECK(checks[1].verdict == Verdict::Pass);
  r.commands.clear();  // ethtool missing
  CHECK(check_nic(r.in)[0].verdict == Verdict::Warn);
}

TEST_CASE("doctor: CAN bit rate, restart-ms and txqueuelen against the configuration", "[doctor]") {
  FakeRoot r;
  r.in.config.bus = BusKind::Canio;
  r.in.config.canio.interface = "can0";
  r.in.config.canio.bitrate = 500000;
  CHECK(check_can(r.in).at(0).verdict == Verdict::Fail);  // no such interface
  r.commands["ip -details -json link show can0"] =
      R"([{"ifname":"can0","txqlen":10,"linkinfo":{"info_kind":"can","info_data":{"restart_ms":0,"bittiming":{"bitrate":250000}}}}])";
  auto checks = check_can(r.in);
  REQUIRE(checks.size() == 3);
  CHECK(checks[0].verdict == Verdict::Fail);
  CHECK(checks[0].detail.find("250000") != std::string::npos);
  CHECK(checks[1].verdict == Verdict::Warn);
  CHECK(checks[2].verdict == Verdict::Warn);
  r.commands["ip -details -json link show can0"] =
      R"([{"ifname":"can0","txqlen":100,"linkinfo":{"info_kind":"can","info_data":{"restart_ms":100,"bittiming":{"bitrate":500000}}}}])";
  checks = check_can(r.in);
  for (const Check& c : checks) CHECK(c.verdict == Verdict::Pass);
  r.in.config.canio.virtual_bus = "sim";  // no interface to check
  CHECK(check_can(r.in).empty());
}

TEST_CASE("doctor: the unit's limits and CPUAffinity", "[doctor]") {
  FakeRoot r;
  r.put("/lib/systemd/system/ds1928d.service",
        "[Service]\nLimitRTPRIO=99\nLimitMEMLOCK=infinity\nCPUAffinity=0 2\n");
  auto checks = check_unit(r.in);
  REQUIRE(checks.size() == 2);
  CHECK(checks[0].verdict == Verdict::Pass);
  CHECK(checks[1].verdict == Verdict::Fail);  // CPU 1 excluded
  r.put("/lib/systemd/system/ds1928d.service", "[Service]\nLimitRTPRIO=50\nCPUAffinity=1-3\n");
  checks = check_unit(r.in);
  CHECK(checks[0].verdict == Verdict::Fail);  // priority 80 > 50, no MEMLOCK
  CHECK(checks[1].verdict == Verdict::Pass);
  // An override in /etc wins over the package's unit.
  r.put("/etc/systemd/system/ds1928d.service",
        "[Service]\nLimitRTPRIO=99\nLimitMEMLOCK=infinity\n");
  checks = check_unit(r.in);
  CHECK(checks[0].verdict == Verdict::Pass);
  CHECK(checks[1].verdict == Verdict::Pass);
  // All checks at once: every check has a name and a verdict; WARN/FAIL have a fix.
  r.put("/proc/cmdline", "quiet");
  for (const Check& c : run_doctor(r.in)) {
    CHECK_FALSE(c.name.empty());
    if (c.verdict != Verdict::Pass) CHECK_FALSE(c.detail.empty());
  }
}

TEST_CASE("doctor: the measured wake-ups are judged against the period", "[doctor]") {
  // 5 s at 1 ms, every cycle started well within its period.
  MeasuredCycles m{5.0, 1000, 4998, 0, 143'000, 999'999};
  Check c = check_measured_cycles(m);
  CHECK(c.name == "measured_wakeup");
  CHECK(c.verdict == Verdict::Pass);
  CHECK_THAT(c.detail, Catch::Contains("4998 cycles at 1000 µs") &&
                           Catch::Contains("max 1000.0 µs") && Catch::Contains("0 overrun(s)"));
  CHECK(c.fix.empty());
  // One wake-up a whole period late (a VM's host stopped the vCPU for 3.9 ms): a missed SoC.
  m.wake_max_ns = 3'885'100;
  c = check_measured_cycles(m);
  CHECK(c.verdict == Verdict::Warn);
  CHECK_THAT(c.detail, Catch::Contains("max 3885.1 µs") && Catch::Contains("SoC"));
  CHECK_THAT(c.fix, Catch::Contains("pinned vCPUs") && Catch::Contains("hwlatdetect"));
  // Exactly one period late is already too late; an overrun alone is too.
  m.wake_max_ns = 1'000'000;
  CHECK(check_measured_cycles(m).verdict == Verdict::Warn);
  m.wake_max_ns = 500'000;
  m.overruns = 1;
  CHECK(check_measured_cycles(m).verdict == Verdict::Warn);
  // No cycle at all: the engine did not run.
  m.cycles = 0;
  c = check_measured_cycles(m);
  CHECK(c.verdict == Verdict::Fail);
  CHECK_THAT(c.detail, Catch::Contains("no cycle in 5.0 s"));
  CHECK_FALSE(c.fix.empty());
}
