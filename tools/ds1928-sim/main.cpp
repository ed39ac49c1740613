// ds1928-sim: standalone simulated node, the test peer of ds1928d.
//   ds1928-sim powerlink --iface IF --node N [--modules K] [--profile hardware|software-cn]
//                        [--drop-pres P] [--delay-pres-us U] [--pres-not-ready]
//                        [--power-cycle-after S] [--config FILE] ...
// runs POWERLINK Controlled Node(s) with simulated X20DS1928 modules on a raw socket and prints
// every NMT state change. SIGUSR1 power-cycles the node(s); SIGUSR2 makes them ask the MN for
// their own reset (NMTRequest); SIGRTMIN makes them raise an error entry (code --error-code,
// signalled to the MN by EN, fetched by StatusRequest; also once by --raise-error-after S);
// SIGINT/SIGTERM stop.
//   ds1928-sim canio (--iface IF | --virtual NAME) [--node N] [--modules K] [--config FILE]
//                    [--drop P] [--wrong-length-every N] [--unexpected-id ID] [--no-sdo]
//                    [--sync-reaction-us US] [--late-object2 P [--late-object2-us US]]
//                    [--self-start] [--heartbeat-ms MS] [--reset-after S] [--stall-after S]
//                    [--emcy-after S] ...
// (SIGUSR1: the CAN-I/O node resets by itself, as --reset-after.)
// runs a CAN-I/O bus controller with simulated X20DS1928 modules (function model 254) on
// SocketCAN or on the cross-process virtual test bus (docs/canio.md).
#include <fcntl.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "canio_main.hpp"
#include "config/config_loader.hpp"
#include "core/clock.hpp"
#include "core/unique_fd.hpp"
#include "powerlink/raw_link.hpp"
#include "sim/powerlink_cn.hpp"

namespace pl = ds1928::powerlink;
namespace sim = ds1928::sim;

namespace {

std::atomic<bool> g_stop{false};
std::atomic<bool> g_power_cycle{false};
std::atomic<bool> g_request_reset{false};
std::atomic<bool> g_raise_error{false};
void on_rtmin(int) {
  g_raise_error.store(true);
}
void on_stop(int) {
  g_stop.store(true);
}
void on_usr1(int) {
  g_power_cycle.store(true);
}
void on_usr2(int) {
  g_request_reset.store(true);
}

struct PowerlinkOptions {
  std::string iface;
  int node = 1;
  int count = 1;
  int modules = 1;
  double drop_pres = 0.0;
  uint32_t delay_pres_us = 0;
  double delay_pres_prob = 1.0;
  int wrong_pres_size = 0;
  bool pres_not_ready = false;
  double power_cycle_after_s = 0.0;
  double raise_error_after_s = 0.0;
  uint16_t error_code = 0x1928;
  uint32_t power_off_ms = 300;
  std::string config_file;
  std::string rx_mode = "ring";
  int rt_priority = 60;
  int cpu = -1;
  uint64_t seed = 1;
  uint32_t guard_us = 80;
  double duration_s = 0.0;
  bool quiet = false;
  bool no_prc = false;
  std::string pdo_mapping = "none";
  // Software response path (--profile software-cn and the --pres-latency-* options).
  std::string profile = "hardware";
  double pres_latency_us = -1;  // -1: from the profile
  double pres_latency_sigma = -1;
  double pres_latency_max_us = -1;
  double ready_after_soc_us = -1;
};

// "software-cn": a CN whose PRes comes from a user-space stack, as on a PC: its responder blocks
// in the kernel until the PReq arrives (blocking receive), runs at SCHED_FIFO 50 — below an MN at
// the usual 80 — on the CPU given by --cpu, answers after a log-normal delay with a long tail and
// not before it finished the SoC's work. Options given explicitly win over the profile.
void apply_profile(PowerlinkOptions& o, const std::vector<std::string>& given) {
  auto was_given = [&](const char* name) {
    return std::find(given.begin(), given.end(), name) != given.end();
  };
  if (o.profile == "software-cn") {
    if (!was_given("--rx-mode")) o.rx_mode = "blocking";
    if (!was_given("--rt-priority")) o.rt_priority = 50;
    // Never asleep on a timer while a PReq may come: the responder waits in the kernel for the
    // frame, as a user-space stack's receive thread does (a SoC earlier than the learned period
    // predicts would otherwise find it sleeping).
    if (!was_given("--guard-us")) o.guard_us = 10'000'000;
    if (o.pres_latency_us < 0) o.pres_latency_us = 30;
    if (o.ready_after_soc_us < 0) o.ready_after_soc_us = 20;
  }
  if (o.pres_latency_us < 0) o.pres_latency_us = 0;
  if (o.pres_latency_sigma < 0) o.pres_latency_sigma = 0.6;
  if (o.pres_latency_max_us < 0) o.pres_latency_max_us = 2000;
  if (o.ready_after_soc_us < 0) o.ready_after_soc_us = 0;
}

// The calling thread's run-queue wait in ns, as the kernel counts it (/proc/thread-self/schedstat:
// time on the CPU, time waiting for one, time slices): how the loop tells a task of this machine
// running instead of it (counted there) from its host not running the vCPU (not counted).
class RunQueueWait {
 public:
  RunQueueWait() : fd_(::open("/proc/thread-self/schedstat", O_RDONLY | O_CLOEXEC)) {}
  [[nodiscard]] bool available() const noexcept { return fd_.valid() && read() >= 0; }
  [[nodiscard]] int64_t read() const noexcept {
    std::array<char, 96> buf{};
    const ssize_t n = ::pread(fd_.get(), buf.data(), buf.size() - 1, 0);
    unsigned long long on_cpu = 0;
    unsigned long long waited = 0;
    if (n <= 0 || std::sscanf(buf.data(), "%llu %llu", &on_cpu, &waited) != 2) return -1;
    return static_cast<int64_t>(waited);
  }

 private:
  ds1928::UniqueFd fd_;
};

// SCHED_FIFO and locked memory when permitted; the simulator still runs (slower) without.
void try_realtime(int priority, int cpu) {
  if (cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) != 0) std::perror("ds1928-sim: CPU affinity");
  }
  if (priority <= 0) return;
  sched_param sp{};
  sp.sched_priority = priority;
  if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) {
    std::fprintf(stderr, "ds1928-sim: SCHED_FIFO not permitted, running with normal priority\n");
    return;
  }
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) std::perror("ds1928-sim: mlockall");
}

// Node configuration from the daemon's YAML: the axes on this node become its modules (slot,
// MTUs, simulated motion), identity expectations and SDO overrides are taken over so the MN's
// checks pass.
[[nodiscard]] bool apply_config_file(const std::string& file, uint8_t node,
                                     sim::PowerlinkCnConfig& cn) {
  auto result = ds1928::load_config(file);
  if (!result) {
    std::fprintf(stderr, "%s", result.error_report().c_str());
    return false;
  }
  const ds1928::DaemonConfig& config = result.config();
  cn.modules.clear();
  for (std::size_t i = 0; i < config.axes.size(); ++i) {
    const ds1928::AxisConfig& axis = config.axes[i];
    if (axis.node != node) continue;
    sim::PowerlinkCnModuleConfig m;
    m.slot = axis.slot;
    m.input_mtu = axis.module.input_mtu;
    m.output_mtu = axis.module.output_mtu;
    m.pres_offset = axis.pres_offset;
    m.preq_offset = axis.preq_offset;
    if (i < config.simulated.axes.size()) m.sim = config.simulated.axes[i];
    cn.modules.push_back(m);
  }
  for (const ds1928::PowerlinkNodeConfig& n : config.powerlink.nodes) {
    if (n.node_id != node) continue;
    if (n.vendor_id) cn.vendor_id = *n.vendor_id;
    if (n.product_code) cn.product_code = *n.product_code;
    if (n.device_type) cn.device_type = *n.device_type;
    if (n.revision_no) cn.revision_no = *n.revision_no;
    if (n.serial_no) cn.serial_no = *n.serial_no;
  }
  cn.sdo_overrides = config.powerlink.sdo_overrides;
  cn.nettime_offset_us = config.powerlink.nettime_offset_us;
  return true;
}

[[nodiscard]] pl::RxMode parse_rx_mode(const std::string& s) {
  if (s == "busy-poll") return pl::RxMode::BusyPoll;
  if (s == "blocking") return pl::RxMode::Blocking;
  return pl::RxMode::Ring;
}

int run_powerlink(const PowerlinkOptions& o) {
  pl::RawLink link;
  pl::RawLinkOptions link_options;
  link_options.interface = o.iface;
  link_options.rx_mode = parse_rx_mode(o.rx_mode);
  if (auto ec = link.open(link_options)) {
    std::fprintf(stderr, "ds1928-sim: cannot open %s: %s\n", o.iface.c_str(), ec.message().c_str());
    return 2;
  }

  std::vector<std::unique_ptr<sim::PowerlinkCn>> nodes;
  std::vector<sim::PowerlinkCn*> node_ptrs;
  const int64_t start = ds1928::rt::now_ns();
  for (int k = 0; k < o.count; ++k) {
    const auto node_id = static_cast<uint8_t>(o.node + k);
    sim::PowerlinkCnConfig cn;
    cn.node_id = node_id;
    cn.mac = link.mac();
    cn.serial_no = node_id;
    cn.modules.clear();
    for (int m = 0; m < o.modules; ++m) {
      sim::PowerlinkCnModuleConfig module;
      module.slot = static_cast<uint8_t>(m + 1);
      cn.modules.push_back(module);
    }
    if (!o.config_file.empty() && !apply_config_file(o.config_file, node_id, cn)) return 1;
    cn.power_off_ns = static_cast<int64_t>(o.power_off_ms) * 1'000'000;
    cn.faults.drop_pres = o.drop_pres;
    cn.faults.delay_pres_ns = static_cast<int64_t>(o.delay_pres_us) * 1000;
    cn.faults.delay_pres = o.delay_pres_us > 0 ? o.delay_pres_prob : 0.0;
    cn.faults.pres_size_delta = o.wrong_pres_size;
    cn.faults.pres_not_ready = o.pres_not_ready;
    cn.faults.seed = o.seed + static_cast<uint64_t>(k);
    cn.response.pres_latency_median_ns = static_cast<int64_t>(o.pres_latency_us * 1000);
    cn.response.pres_latency_sigma = o.pres_latency_sigma;
    cn.response.pres_latency_max_ns = static_cast<int64_t>(o.pres_latency_max_us * 1000);
    cn.response.ready_after_soc_ns = static_cast<int64_t>(o.ready_after_soc_us * 1000);
    cn.prc_capable = !o.no_prc;
    cn.own_mapping = o.pdo_mapping == "packed"           ? sim::OwnMapping::kPacked
                     : o.pdo_mapping == "poscycle-first" ? sim::OwnMapping::kPosCycleFirst
                     : o.pdo_mapping == "gap"            ? sim::OwnMapping::kGap
                                                         : sim::OwnMapping::kNone;
    // The wire shows every node's frames to the others; a socket does not return its own, so a
    // SyncResponse (which the other nodes time for PollResponse Chaining) is handed to the other
    // nodes of this process here.
    std::unique_ptr<sim::PowerlinkCn> node;
    try {
      node = std::make_unique<sim::PowerlinkCn>(
          cn, [&link, &node_ptrs, node_id](std::span<const uint8_t> frame) {
            (void)link.send(frame);
            if (frame.size() > 17 && frame[14] == 0x06 && frame[17] == 0x06) {
              const int64_t now = ds1928::rt::now_ns();
              for (sim::PowerlinkCn* other : node_ptrs)
                if (other->node_id() != node_id) other->receive(frame, now);
            }
          });
    } catch (const std::invalid_argument& e) {
      std::fprintf(stderr, "ds1928-sim: node %u: %s\n", node_id, e.what());
      return 1;
    }
    if (!o.quiet) {
      node->set_state_listener([node_id, start](pl::NmtState from, pl::NmtState to, int64_t t) {
        std::printf("%10.6f node %u: %s -> %s\n",
                    static_cast<double>((t > 0 ? t : ds1928::rt::now_ns()) - start) / 1e9, node_id,
                    std::string(pl::to_string(from)).c_str(),
                    std::string(pl::to_string(to)).c_str());
        std::fflush(stdout);
      });
    }
    std::printf(
        "node %u: %zu module(s), PRes payload %u bytes, PReq payload %u bytes, MAC "
        "%02x:%02x:%02x:%02x:%02x:%02x on %s (%s, profile %s, PRes latency median %.0f us "
        "sigma %.2f, ready %.0f us after SoC)\n",
        node_id, node->module_count(), node->layout().pres_size, node->layout().preq_size,
        cn.mac[0], cn.mac[1], cn.mac[2], cn.mac[3], cn.mac[4], cn.mac[5], o.iface.c_str(),
        pl::to_string(link.rx_mode()), o.profile.c_str(), o.pres_latency_us, o.pres_latency_sigma,
        o.ready_after_soc_us);
    node_ptrs.push_back(node.get());
    nodes.push_back(std::move(node));
  }
  std::fflush(stdout);

  try_realtime(o.rt_priority, o.cpu);
  sim::PowerlinkCnLoop::Options loop_options;
  loop_options.guard_ns = static_cast<int64_t>(o.guard_us) * 1000;
  // Opened by the thread that runs the loop (this one). Without it every stall counts as silence.
  RunQueueWait run_queue_wait;
  if (run_queue_wait.available()) {
    loop_options.run_queue_wait_ns = [&run_queue_wait] { return run_queue_wait.read(); };
  } else {
    std::fprintf(stderr,
                 "ds1928-sim: no /proc/thread-self/schedstat: the simulator's own stalls count as "
                 "loss of SoC\n");
  }
  sim::PowerlinkCnLoop loop(
      link, [&link](int64_t deadline) { return link.wait_readable(deadline); }, node_ptrs,
      loop_options);

  const int64_t power_cycle_at =
      o.power_cycle_after_s > 0 ? start + static_cast<int64_t>(o.power_cycle_after_s * 1e9) : 0;
  bool power_cycled = false;
  const int64_t raise_error_at =
      o.raise_error_after_s > 0 ? start + static_cast<int64_t>(o.raise_error_after_s * 1e9) : 0;
  bool error_raised = false;
  uint64_t errors_raised = 0;
  const int64_t stop_at = o.duration_s > 0 ? start + static_cast<int64_t>(o.duration_s * 1e9) : 0;
  bool link_was_up = link.link_up();
  while (!g_stop.load(std::memory_order_relaxed)) {
    if (!loop.run_once()) {
      // Link error (interface gone or down): say so once per transition, keep trying.
      timespec ts{0, 10'000'000};
      nanosleep(&ts, nullptr);
    }
    const int64_t now = ds1928::rt::now_ns();
    if ((power_cycle_at != 0 && !power_cycled && now >= power_cycle_at) ||
        g_power_cycle.exchange(false)) {
      power_cycled = true;
      std::printf("%10.6f power cycle\n", static_cast<double>(now - start) / 1e9);
      std::fflush(stdout);
      for (auto* n : node_ptrs) n->power_cycle(now);
    }
    if ((raise_error_at != 0 && !error_raised && now >= raise_error_at) ||
        g_raise_error.exchange(false)) {
      error_raised = true;
      ++errors_raised;
      std::printf("%10.6f error entry 0x%04X raised (%llu)\n",
                  static_cast<double>(now - start) / 1e9, o.error_code,
                  static_cast<unsigned long long>(errors_raised));
      std::fflush(stdout);
      // Additional information: which raise this was, so a test can tell entries apart.
      std::array<uint8_t, 8> info{};
      for (int b = 0; b < 8; ++b) info[b] = static_cast<uint8_t>(errors_raised >> (8 * b));
      for (auto* n : node_ptrs) n->raise_error(o.error_code, info, now);
    }
    if (g_request_reset.exchange(false)) {
      std::printf("%10.6f NMTRequest: reset of own node queued\n",
                  static_cast<double>(now - start) / 1e9);
      std::fflush(stdout);
      for (auto* n : node_ptrs) n->request_own_reset();
    }
    if (link.link_up() != link_was_up) {
      link_was_up = link.link_up();
      std::printf("%10.6f link %s\n", static_cast<double>(now - start) / 1e9,
                  link_was_up ? "up" : "down");
      std::fflush(stdout);
    }
    if (stop_at != 0 && now >= stop_at) break;
  }
  for (auto* n : node_ptrs) {
    const sim::PowerlinkCnStats& s = n->stats();
    std::printf(
        "node %u stats: soc=%llu preq=%llu pres=%llu dropped=%llu delayed=%llu soa=%llu "
        "asnd=%llu nmt=%llu sdo_in=%llu loss_soc=%llu loss_preq=%llu preq_out_of_slot=%llu "
        "resets=%llu "
        "bad=%llu short=%llu sync_req=%llu pres_mn=%llu pres_mn_outputs=%llu prc=%s "
        "prc_fallbacks=%llu "
        "pres_time_first_ns=%u own_stalls=%llu own_stall_max_us=%lld state=%s\n",
        n->node_id(), static_cast<unsigned long long>(s.soc),
        static_cast<unsigned long long>(s.preq), static_cast<unsigned long long>(s.pres_sent),
        static_cast<unsigned long long>(s.pres_dropped),
        static_cast<unsigned long long>(s.pres_delayed), static_cast<unsigned long long>(s.soa),
        static_cast<unsigned long long>(s.asnd_sent),
        static_cast<unsigned long long>(s.nmt_commands),
        static_cast<unsigned long long>(s.sdo_frames_in),
        static_cast<unsigned long long>(s.loss_of_soc),
        static_cast<unsigned long long>(s.loss_of_preq),
        static_cast<unsigned long long>(s.preq_out_of_slot),
        static_cast<unsigned long long>(s.resets), static_cast<unsigned long long>(s.bad_frames),
        static_cast<unsigned long long>(s.short_frames),
        static_cast<unsigned long long>(s.sync_requests),
        static_cast<unsigned long long>(s.pres_mn),
        static_cast<unsigned long long>(s.pres_mn_outputs), n->prc_mode() ? "yes" : "no",
        static_cast<unsigned long long>(s.prc_fallbacks), n->pres_time_first_ns(),
        static_cast<unsigned long long>(s.own_stalls),
        static_cast<long long>(s.own_stall_max_ns / 1000),
        std::string(pl::to_string(n->nmt_state())).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ds1928-sim: simulated X20DS1928 node for ds1928d"};
  app.require_subcommand(1);

  PowerlinkOptions o;
  CLI::App* plk = app.add_subcommand("powerlink", "POWERLINK Controlled Node on a raw socket");
  plk->add_option("--iface", o.iface, "Ethernet interface")->required();
  plk->add_option("--node", o.node, "node id (first of --count nodes)")->check(CLI::Range(1, 239));
  plk->add_option("--count", o.count, "simulate nodes N .. N+count-1 on the same port")
      ->check(CLI::Range(1, 64));
  plk->add_option("--modules", o.modules, "X20DS1928 modules per node (slots 1..K)")
      ->check(CLI::Range(0, 16));
  plk->add_option("--drop-pres", o.drop_pres, "probability that a PRes is not sent")
      ->check(CLI::Range(0.0, 1.0));
  plk->add_option("--delay-pres-us", o.delay_pres_us, "send PRes this much late");
  plk->add_option("--delay-pres-prob", o.delay_pres_prob,
                  "probability that a PRes is delayed (with --delay-pres-us)")
      ->check(CLI::Range(0.0, 1.0));
  plk->add_option("--wrong-pres-size", o.wrong_pres_size,
                  "PRes payload this many bytes longer (negative: shorter)");
  plk->add_flag("--pres-not-ready", o.pres_not_ready,
                "PRes with RD = 0 also in OPERATIONAL (data not ready: the MN must not take it)");
  plk->add_option("--power-cycle-after", o.power_cycle_after_s,
                  "power-cycle the node(s) once after S seconds (SIGUSR1: now)");
  plk->add_option("--raise-error-after", o.raise_error_after_s,
                  "raise an error entry once after S seconds (SIGRTMIN: now)");
  plk->add_option("--error-code", o.error_code, "code of the raised error entries");
  plk->add_option("--power-off-ms", o.power_off_ms, "how long a power cycle keeps the node off");
  plk->add_option("--config", o.config_file,
                  "daemon YAML: modules (axes on this node), identity, SDO overrides");
  plk->add_option("--rx-mode", o.rx_mode, "ring | busy-poll | blocking")
      ->check(CLI::IsMember({"ring", "busy-poll", "blocking"}));
  plk->add_option("--rt-priority", o.rt_priority, "SCHED_FIFO priority (0: normal scheduling)")
      ->check(CLI::Range(0, 99));
  plk->add_option("--cpu", o.cpu, "pin to this CPU");
  plk->add_option("--seed", o.seed, "fault injection random seed");
  plk->add_option("--guard-us", o.guard_us, "start polling this long before the next SoC");
  plk->add_option("--duration", o.duration_s, "stop after S seconds (0: until SIGTERM)");
  plk->add_flag("--quiet", o.quiet, "do not print NMT state changes");
  plk->add_flag("--no-prc", o.no_prc,
                "no PollResponse Chaining: the PRC feature flag is not advertised and an MN's "
                "SyncRequests do not switch the node to PRC");
  plk->add_option("--pdo-mapping", o.pdo_mapping,
                  "the node's own PDO mapping (0x1A00/0x1600, readable by SDO): none (disabled, "
                  "packed image) | packed | poscycle-first (PosCycle before PositionLW) | gap "
                  "(a byte no object is mapped to after every register)")
      ->check(CLI::IsMember({"none", "packed", "poscycle-first", "gap"}));
  plk->add_option("--profile", o.profile,
                  "hardware (PRes at once, polling) | software-cn (blocking responder at FIFO 50, "
                  "PRes latency with a long tail, readiness delay after SoC)")
      ->check(CLI::IsMember({"hardware", "software-cn"}));
  plk->add_option("--pres-latency-us", o.pres_latency_us,
                  "median PRes latency, log-normal (software-cn: 30)");
  plk->add_option("--pres-latency-sigma", o.pres_latency_sigma,
                  "log-normal shape of the PRes latency (0.6: p99 = 4 x median)");
  plk->add_option("--pres-latency-max-us", o.pres_latency_max_us, "cap of the PRes latency");
  plk->add_option("--ready-after-soc-us", o.ready_after_soc_us,
                  "no PRes earlier than this after the SoC (software-cn: 20)");

  CanioOptions co;
  CLI::App* can = app.add_subcommand(
      "canio", "CAN-I/O bus controller with X20DS1928 modules (function model 254)");
  auto* iface = can->add_option("--iface", co.iface, "SocketCAN interface (e.g. can1)");
  auto* virt = can->add_option("--virtual", co.virtual_bus,
                               "the cross-process virtual test bus of this name instead");
  iface->excludes(virt);
  can->add_option("--node", co.node, "node number of the bus controller")
      ->check(CLI::Range(1, 127));
  can->add_option("--modules", co.modules,
                  "X20DS1928 modules (slots 1..K, analog slots 1, 3, ...; without --config)")
      ->check(CLI::Range(1, 8));
  can->add_option("--config", co.config_file,
                  "daemon YAML: the axes on --node become the modules (identifiers, SYNC, byte "
                  "order, SDO objects, simulated motion)");
  can->add_option("--bitrate", co.bitrate, "expected interface bit rate (default: the config's)");
  can->add_option("--byte-order", co.byte_order, "little | big (without --config)")
      ->check(CLI::IsMember({"little", "big"}));
  can->add_flag("--no-sync", co.no_sync,
                "answer output objects instead of SYNC (without --config)");
  can->add_option("--sync-id", co.sync_id, "SYNC identifier (without --config)");
  can->add_option("--drop", co.drop, "probability that an input object is not sent")
      ->check(CLI::Range(0.0, 1.0));
  can->add_option("--wrong-length-every", co.wrong_length_every,
                  "every N-th position object with 7 instead of 8 bytes");
  can->add_option("--unexpected-id", co.unexpected_id,
                  "also send a frame with this identifier after every SYNC");
  can->add_flag("--no-sdo", co.no_sdo, "ignore SDO requests (no acyclic access)");
  can->add_option("--sync-reaction-us", co.sync_reaction_us,
                  "answer a SYNC this long after its reception (bus-controller reaction; "
                  "default 50, an assumption)")
      ->check(CLI::Range(0, 100000));
  can->add_option("--late-object2", co.late_object2,
                  "probability that input object 2 goes out --late-object2-us late")
      ->check(CLI::Range(0.0, 1.0));
  can->add_option("--late-object2-us", co.late_object2_us,
                  "how late object 2 goes out (default: one cycle of the config, else 2000)")
      ->check(CLI::Range(0, 1000000));
  can->add_option("--answer-log", co.answer_log,
                  "write one line per answer: SYNC count, slot, position, PosCycle");
  can->add_option("--silent-after", co.silent_after_s, "stop answering after S seconds");
  can->add_option("--silent-for-ms", co.silent_for_ms, "... for this long (0: for good)");
  can->add_flag("--power-cycle-when-back", co.power_cycle_when_back,
                "modules come back with their bus-controller defaults (EnDat disabled)");
  can->add_flag("--self-start", co.self_start,
                "operational right after the boot-up message (default: a strict CANopen node "
                "waits pre-operational for NMT Start)");
  can->add_option("--heartbeat-ms", co.heartbeat_ms,
                  "heartbeat producer time at power-up (object 0x1017; default 0: until the "
                  "master sets it)")
      ->check(CLI::Range(0, 65535));
  can->add_flag("--config-readable", co.config_readable,
                "configuration registers answer reads (default: write-only, as the FM254 "
                "register table lists them)");
  can->add_option("--reset-after", co.reset_after_s,
                  "reset by itself after S seconds (brown-out: boot-up, pre-operational, the "
                  "modules' settings lost)");
  can->add_option("--stall-after", co.stall_after_s,
                  "the acquisition stalls after S seconds (same position and PosCycle resent)");
  can->add_option("--stall-for-ms", co.stall_for_ms, "... for this long (0: for good)");
  can->add_option("--emcy-after", co.emcy_after_s, "send one EMCY after S seconds");
  can->add_option("--emcy-code", co.emcy_code, "its error code (default 0x7300)")
      ->check(CLI::Range(0, 65535));
  for (auto [flag, field, what] :
       {std::tuple{"--device-type", &co.device_type, "device type (object 0x1000)"},
        std::tuple{"--vendor-id", &co.vendor_id, "vendor-ID (0x1018/1)"},
        std::tuple{"--product-code", &co.product_code, "product code (0x1018/2)"},
        std::tuple{"--revision-no", &co.revision_no, "revision number (0x1018/3)"},
        std::tuple{"--serial-no", &co.serial_no, "serial number (0x1018/4)"}})
    can->add_option(flag, *field,
                    std::string("identity: ") + what +
                        " (default: the config's canio.nodes[] entry, else a placeholder)")
        ->check(CLI::Range(int64_t{0}, int64_t{0xFFFFFFFF}));
  can->add_flag("--no-identity", co.no_identity,
                "no identity objects: reads of 0x1000 / 0x1018 abort with 0x06020000");
  can->add_option("--seed", co.seed, "fault injection random seed");
  can->add_option("--duration", co.duration_s, "stop after S seconds (0: until SIGTERM)");

  CLI11_PARSE(app, argc, argv);
  if (can->parsed() && co.iface.empty() == co.virtual_bus.empty()) {
    std::fprintf(stderr, "ds1928-sim canio: give --iface IFACE or --virtual NAME\n");
    return 2;
  }
  std::signal(SIGINT, on_stop);
  std::signal(SIGTERM, on_stop);
  std::signal(SIGUSR1, on_usr1);
  std::signal(SIGUSR2, on_usr2);
  std::signal(SIGRTMIN, on_rtmin);
  setvbuf(stdout, nullptr, _IOLBF, 0);
  if (plk->parsed()) {
    std::vector<std::string> given;
    for (const CLI::Option* opt : plk->get_options())
      if (opt->count() > 0 && !opt->get_lnames().empty())
        given.push_back("--" + opt->get_lnames()[0]);
    apply_profile(o, given);
    return run_powerlink(o);
  }
  // SIGUSR1 power-cycles the CAN-I/O node too (a reset by itself: boot-up, settings lost).
  if (can->parsed()) return run_canio(co, g_stop, g_power_cycle);
  return 1;
}
