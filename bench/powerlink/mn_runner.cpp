// Managing Node runner: PowerlinkBus on a raw socket, cycled on SCHED_FIFO at an absolute
// period, with measurements on the wire side of the link (SoC-to-SoC interval, PReq→PRes
// latency, wake-up latency) and checks on what would be published (positions against the
// simulated motion, NetTime stamps). Used by bench/powerlink/run_cycle_bench.sh and by the
// namespace integration test (tests/integration/powerlink_veth_test.sh).
//
// Output: "EVENT ..." lines on CN boot-state changes, "RESULT/JITTER/LATENCY/WAKE ..." at the end.
// Exit status 3 when a wrong position or a bad time stamp was seen.
#include <fcntl.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <string>
#include <vector>

#include "config/config_loader.hpp"
#include "core/axis_sample.hpp"
#include "core/clock.hpp"
#include "powerlink/cycle_budget.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "powerlink/raw_link.hpp"
#include "powerlink/rx_wait.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace pl = ds1928::powerlink;

namespace {

std::atomic<bool> g_stop{false};
void on_stop(int) {
  g_stop.store(true);
}

// Fixed-bin histogram (100 ns bins): exact enough percentiles without storing samples and
// without allocating on the cycle path.
class Histogram {
 public:
  explicit Histogram(int64_t max_ns) : bins_(static_cast<std::size_t>(max_ns / kBinNs) + 1, 0) {}
  void add(int64_t ns) noexcept {
    if (ns < 0) ns = 0;
    const auto bin = std::min<std::size_t>(static_cast<std::size_t>(ns / kBinNs), bins_.size() - 1);
    ++bins_[bin];
    ++count_;
    max_ = std::max(max_, ns);
  }
  [[nodiscard]] double percentile_us(double p) const noexcept {
    if (count_ == 0) return 0.0;
    const auto target = static_cast<uint64_t>(std::ceil(p * static_cast<double>(count_)));
    uint64_t seen = 0;
    for (std::size_t i = 0; i < bins_.size(); ++i) {
      seen += bins_[i];
      if (seen >= target) return static_cast<double>(i * kBinNs) / 1000.0;
    }
    return max_us();
  }
  [[nodiscard]] double max_us() const noexcept { return static_cast<double>(max_) / 1000.0; }
  [[nodiscard]] uint64_t count() const noexcept { return count_; }

 private:
  static constexpr int64_t kBinNs = 100;
  std::vector<uint32_t> bins_;
  uint64_t count_ = 0;
  int64_t max_ = 0;
};

// Link decorator that time-stamps what the MN puts on and takes off the wire.
class MeasuringLink final : public pl::Link {
 public:
  explicit MeasuringLink(pl::RawLink& inner, int64_t period_ns)
      : inner_(inner), period_ns_(period_ns), soc_jitter_(20'000'000), latency_(20'000'000) {}

  std::error_code send(std::span<const uint8_t> frame) noexcept override {
    const int64_t t = ds1928::rt::now_ns();
    if (frame.size() > 16) {
      const uint8_t type = frame[14] & 0x7F;
      if (type == 0x01) {
        if (measuring && last_soc_ != 0) {
          soc_jitter_.add(std::llabs((t - last_soc_) - period_ns_));
          soc_interval_max_ = std::max(soc_interval_max_, t - last_soc_);
        }
        last_soc_ = t;
        soc_sent_ns = t;
      } else if (type == 0x03) {
        preq_time_[frame[15]] = t;
      }
    }
    const std::error_code ec = inner_.send(frame);
    if (frame.size() > 16 && (frame[14] & 0x7F) == 0x01) soc_send_done_ns = ds1928::rt::now_ns();
    return ec;
  }
  pl::Received receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept override {
    pl::Received r = inner_.receive(buffer, deadline_ns);
    if (measuring && r.length > 16 && (buffer[14] & 0x7F) == 0x04) {
      const uint8_t node = buffer[16];
      if (preq_time_[node] != 0) {
        latency_.add(r.rx_time_ns - preq_time_[node]);
        // Answered, but after the MN gave up: the CN side (its host) was late, not silent.
        if (r.rx_time_ns - preq_time_[node] > pres_timeout_ns) ++late_pres;
        preq_time_[node] = 0;
      }
    }
    return r;
  }
  bool link_up() const noexcept override { return inner_.link_up(); }
  pl::MacAddress mac() const noexcept override { return inner_.mac(); }

  bool measuring = false;
  int64_t pres_timeout_ns = 100'000;
  uint64_t late_pres = 0;
  int64_t soc_sent_ns = 0;       // this cycle's SoC was handed to the socket at this instant
  int64_t soc_send_done_ns = 0;  // ... and the send call returned at this one
  const Histogram& soc_jitter() const { return soc_jitter_; }
  const Histogram& latency() const { return latency_; }
  int64_t soc_interval_max_ns() const { return soc_interval_max_; }

 private:
  pl::RawLink& inner_;
  int64_t period_ns_;
  int64_t last_soc_ = 0;
  int64_t soc_interval_max_ = 0;
  std::array<int64_t, 256> preq_time_{};
  Histogram soc_jitter_;
  Histogram latency_;
};

struct Options {
  std::string iface;
  std::string config_file;
  int nodes = 1;
  uint32_t period_us = 0;        // 0: from the config (1000 without one)
  uint32_t pres_timeout_us = 0;  // 0: from the config (200 without one)
  int64_t loss_threshold = -1;   // -1: from the config
  double duration_s = 0;         // measured run after all CNs are operational (0: until signal)
  double warmup_s = 1.0;
  double boot_timeout_s = 20.0;
  int rt_priority = 80;
  int cpu = -1;
  bool check_positions = true;
  std::string rx_mode;  // legacy: ring (= spin) | busy-poll | blocking (recv + ppoll, no ring)
  std::string rx_wait;  // block | spin | busy_poll; default: the configuration's (block)
  int64_t rx_spin_us = -1;
  int64_t wait_soc_preq_us = -1;
  int64_t async_timeout_us = -1;
};

void try_realtime(int priority, int cpu) {
  if (cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) != 0) std::perror("affinity");
  }
  if (priority > 0) {
    sched_param sp{};
    sp.sched_priority = priority;
    if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) std::fprintf(stderr, "no SCHED_FIFO\n");
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) std::perror("mlockall");
  }
}

ds1928::DaemonConfig generated_config(int nodes) {
  ds1928::DaemonConfig c;
  c.bus = ds1928::BusKind::Powerlink;
  c.cycle.period_us = 1000;
  for (int n = 1; n <= nodes; ++n) {
    ds1928::PowerlinkNodeConfig node;
    node.node_id = static_cast<uint8_t>(n);
    c.powerlink.nodes.push_back(node);
    ds1928::AxisConfig axis;
    axis.name = "axis" + std::to_string(n - 1);
    axis.node = static_cast<uint8_t>(n);
    axis.slot = 1;
    c.axes.push_back(axis);
  }
  return c;
}

[[nodiscard]] timespec to_ts(int64_t ns) {
  return timespec{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

struct AxisCheck {
  double velocity = 0;  // periods/s; NaN = motion not checkable
  bool have_prev = false;
  double prev_pos = 0;
  int64_t prev_time = 0;
  ds1928::AxisDecodeState decode;
  ds1928::AxisDecodeParams params;
};

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"POWERLINK Managing Node runner (benchmark and integration test driver)"};
  app.add_option("--iface", o.iface, "interface")->required();
  app.add_option("--config", o.config_file, "daemon YAML (powerlink section, axes, cycle)");
  app.add_option("--nodes", o.nodes, "without --config: CNs 1..N, one X20DS1928 each")
      ->check(CLI::Range(1, 64));
  app.add_option("--period-us", o.period_us, "cycle period");
  app.add_option("--pres-timeout-us", o.pres_timeout_us, "PRes timeout of every CN");
  app.add_option("--loss-threshold", o.loss_threshold, "loss-of-PRes threshold (0 disables)");
  app.add_option("--duration", o.duration_s, "measured seconds after all CNs are operational");
  app.add_option("--warmup", o.warmup_s, "seconds after boot before measuring");
  app.add_option("--boot-timeout", o.boot_timeout_s, "give up when not all operational by then");
  app.add_option("--rt-priority", o.rt_priority, "SCHED_FIFO priority (0: normal)");
  app.add_option("--cpu", o.cpu, "pin to this CPU");
  app.add_option("--rx-mode", o.rx_mode, "raw link mode: ring (spin) | busy-poll | blocking");
  app.add_option("--rx-wait", o.rx_wait, "powerlink.rx_wait: block | spin | busy_poll")
      ->check(CLI::IsMember({"block", "spin", "busy_poll"}));
  app.add_option("--rx-spin-us", o.rx_spin_us, "powerlink.rx_spin_us (block: ring polled first)");
  app.add_option("--wait-soc-preq-us", o.wait_soc_preq_us, "WaitSoCPReq (0x1F8A/1)");
  app.add_option("--async-timeout-us", o.async_timeout_us, "AsyncSlotTimeout (0x1F8A/2)");
  app.add_flag("!--no-check-positions", o.check_positions, "do not check positions");
  CLI11_PARSE(app, argc, argv);
  std::signal(SIGINT, on_stop);
  std::signal(SIGTERM, on_stop);
  setvbuf(stdout, nullptr, _IOLBF, 0);

  ds1928::DaemonConfig config;
  if (!o.config_file.empty()) {
    auto loaded = ds1928::load_config(o.config_file);
    if (!loaded) {
      std::fprintf(stderr, "%s", loaded.error_report().c_str());
      return 2;
    }
    config = std::move(loaded).config();
  } else {
    config = generated_config(o.nodes);
  }
  if (o.period_us != 0) config.cycle.period_us = o.period_us;
  for (auto& n : config.powerlink.nodes) {
    if (o.pres_timeout_us != 0) n.pres_timeout_us = o.pres_timeout_us;
  }
  if (o.loss_threshold >= 0)
    config.powerlink.thresholds.loss_of_pres = static_cast<uint32_t>(o.loss_threshold);
  config.powerlink.interface = o.iface;
  if (o.rx_wait == "block") config.powerlink.rx_wait = ds1928::RxWait::Block;
  if (o.rx_wait == "spin") config.powerlink.rx_wait = ds1928::RxWait::Spin;
  if (o.rx_wait == "busy_poll") config.powerlink.rx_wait = ds1928::RxWait::BusyPoll;
  if (o.rx_spin_us >= 0) config.powerlink.rx_spin_us = static_cast<uint32_t>(o.rx_spin_us);
  if (o.wait_soc_preq_us >= 0)
    config.powerlink.wait_soc_preq_us = static_cast<uint32_t>(o.wait_soc_preq_us);
  if (o.async_timeout_us >= 0)
    config.powerlink.async_timeout_us = static_cast<uint32_t>(o.async_timeout_us);

  pl::RawLink raw;
  pl::RawLinkOptions lo;
  lo.interface = o.iface;
  pl::apply_rx_wait(config.powerlink.rx_wait, config.powerlink.rx_spin_us, lo);
  if (!o.rx_mode.empty()) {
    lo.ring_spin_ns = -1;
    lo.rx_mode = o.rx_mode == "busy-poll"  ? pl::RxMode::BusyPoll
                 : o.rx_mode == "blocking" ? pl::RxMode::Blocking
                                           : pl::RxMode::Ring;
  }
  {
    std::vector<pl::BudgetNode> budget_nodes;
    for (const auto& n : config.powerlink.nodes)
      budget_nodes.push_back({n.node_id, 9, 23, n.pres_timeout_us,
                              n.multiplexed ? n.multiplex_slot.value_or(0) : uint8_t{0}, false,
                              n.pres_latency_us});
    pl::BudgetNetwork net;
    net.wait_soc_preq_us = config.powerlink.wait_soc_preq_us;
    net.async_slot_timeout_us = config.powerlink.async_timeout_us;
    net.async_mtu = config.powerlink.async_mtu;
    net.multiplex_cycles = config.powerlink.multiplex_cycles;
    const pl::CycleBudget nominal = pl::cycle_budget(budget_nodes, net, pl::BudgetCase::kNominal);
    const pl::CycleBudget worst = pl::cycle_budget(budget_nodes, net, pl::BudgetCase::kWorst);
    std::printf(
        "CONFIG period_us=%u rx_wait=%s rx_spin_us=%u ring_spin_ns=%lld rx_mode=%s "
        "wait_soc_preq_us=%u async_slot_timeout_us=%u budget_nominal_us=%.1f "
        "budget_worst_us=%.1f\n",
        config.cycle.period_us, pl::to_string(config.powerlink.rx_wait),
        config.powerlink.rx_spin_us, static_cast<long long>(lo.ring_spin_ns),
        pl::to_string(lo.rx_mode), config.powerlink.wait_soc_preq_us,
        config.powerlink.async_timeout_us, nominal.total_us(), worst.total_us());
  }
  if (auto ec = raw.open(lo)) {
    std::fprintf(stderr, "open %s: %s\n", o.iface.c_str(), ec.message().c_str());
    return 2;
  }
  const int64_t period_ns = static_cast<int64_t>(config.cycle.period_us) * 1000;
  MeasuringLink link(raw, period_ns);

  pl::MnConfig mn;
  mn.bus = config.powerlink;
  mn.axes = config.axes;
  mn.cycle_us = config.cycle.period_us;
  mn.mac = raw.mac();
  std::unique_ptr<pl::PowerlinkBus> bus;
  try {
    bus = std::make_unique<pl::PowerlinkBus>(mn, link);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "MN configuration: %s\n", e.what());
    return 2;
  }
  // A fresh veth reports carrier only after the kernel's link watch ran (up to a second).
  for (int i = 0; i < 300 && !link.link_up(); ++i) usleep(10'000);
  if (auto ec = bus->start()) {
    std::fprintf(stderr, "start: %s\n", ec.message().c_str());
    return 2;
  }

  std::vector<ds1928::AxisIo> axes(config.axes.size());
  std::vector<AxisCheck> checks(config.axes.size());
  for (std::size_t i = 0; i < checks.size(); ++i) {
    const ds1928::SimAxisConfig sim =
        i < config.simulated.axes.size() ? config.simulated.axes[i] : ds1928::SimAxisConfig{};
    checks[i].velocity = sim.profile == ds1928::MotionProfile::ConstantVelocity
                             ? sim.velocity_periods_per_s
                             : std::nan("");
    checks[i].params.signed_format = config.axes[i].module.position_signed;
    // As the daemon decodes: a late PRes taken for a later cycle shows as too old a stamp.
    checks[i].params.max_stamp_age_ns =
        ds1928::default_max_stamp_age_ns(int64_t{config.cycle.period_us} * 1000);
  }

  // cpu_dma_latency 0 for the run: deep C-states add tens of µs to each wake-up.
  const int dma_fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
  if (dma_fd >= 0) {
    const int32_t zero = 0;
    if (write(dma_fd, &zero, sizeof zero) != sizeof zero) std::perror("cpu_dma_latency");
  }
  try_realtime(o.rt_priority, o.cpu);

  Histogram wake(20'000'000);
  Histogram ref_error(20'000'000);
  // The cycle thread's own work per cycle: from its wake-up to the end of the cycle's work
  // (the exchange, decoding and this runner's checks), what competes with the period.
  Histogram work(20'000'000);
  uint64_t measured_overruns = 0;
  uint32_t resets_at_start = 0;
  uint32_t min_timeout_us = UINT32_MAX;
  for (const auto& n : config.powerlink.nodes)
    min_timeout_us = std::min(min_timeout_us, n.pres_timeout_us);
  const int64_t stall_ns =
      static_cast<int64_t>(min_timeout_us == UINT32_MAX ? 100 : min_timeout_us) * 1000;
  link.pres_timeout_ns = stall_ns;
  uint64_t last_stall = UINT64_MAX, stalls = 0;
  uint32_t prev_fired = 0, prev_events = 0;
  uint64_t fired_after_stall = 0, fired_other = 0, losses_after_stall = 0, losses_other = 0;
  std::array<int64_t, 8> stall_window{};
  std::vector<pl::CnBootState> last_boot(config.powerlink.nodes.size(), pl::CnBootState::kIdentify);
  std::vector<uint32_t> boots_at_measure(config.powerlink.nodes.size(), 0);
  uint64_t fresh = 0, wrong = 0, bad_stamp = 0, moving = 0, overruns = 0, cycles = 0;
  uint64_t old_stamps = 0;
  uint64_t measured_cycles = 0;
  // Grid slots the measured window skipped after overruns: executed + skipped cover the window,
  // so a test can tell a loaded host (slots skipped, each accounted) from a lost cycle.
  uint64_t measured_skipped = 0;
  uint32_t fired_at_start = 0, events_at_start = 0;
  bool all_op = false, measuring = false, readback_done = false, readback_sent = false;
  int readback_failures = 0;
  const int64_t start = ds1928::rt::now_ns();
  int64_t all_op_at = 0, measure_from = 0, measure_until = 0;
  int exit_code = 0;

  auto loss_totals = [&](uint32_t& fired, uint32_t& events) {
    fired = 0;
    events = 0;
    for (const pl::CnStatus& st : bus->managing_node().nodes()) {
      fired += st.loss_of_pres.fired;
      events += st.loss_of_pres.events;
    }
  };

  int64_t next = (ds1928::rt::now_ns() / period_ns + 10) * period_ns;
  uint64_t index = 0;
  while (!g_stop.load(std::memory_order_relaxed)) {
    const timespec ts = to_ts(next);
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    const int64_t woke = ds1928::rt::now_ns();
    if (measuring) wake.add(woke - next);
    const ds1928::ExchangeResult res = bus->exchange(axes, next, index);
    const int64_t exchanged = ds1928::rt::now_ns();
    // Stall attribution: a cycle thread that wakes later than the shortest PRes timeout, or a
    // cycle that overran, cannot keep the CNs' PRes in time whatever the protocol code does.
    // Losses and threshold events within a few cycles after such a stall are counted apart.
    if (woke - next > stall_ns || ds1928::rt::now_ns() - next > period_ns) last_stall = index;
    if (measuring) {
      uint32_t f = 0, e = 0;
      loss_totals(f, e);
      const bool after_stall = last_stall != UINT64_MAX && index - last_stall <= 5;
      if (f > prev_fired) (after_stall ? fired_after_stall : fired_other) += f - prev_fired;
      if (e > prev_events) (after_stall ? losses_after_stall : losses_other) += e - prev_events;
      if (woke - next > stall_ns) ++stalls;
      prev_fired = f;
      prev_events = e;
    }
    ++cycles;
    if (measuring) ++measured_cycles;
    const double t_s = static_cast<double>(woke - start) / 1e9;

    // Boot-state changes of the CNs.
    const auto nodes = bus->managing_node().nodes();
    for (std::size_t k = 0; k < nodes.size() && k < last_boot.size(); ++k) {
      if (nodes[k].boot != last_boot[k]) {
        std::printf(
            "EVENT t=%.3f node=%u boot=%s nmt=%s boots=%u resets=%u pres_losses=%u "
            "last_error=\"%s\"\n",
            t_s, nodes[k].node, std::string(pl::to_string(nodes[k].boot)).c_str(),
            std::string(pl::to_string(nodes[k].nmt)).c_str(), nodes[k].boots, nodes[k].resets,
            nodes[k].loss_of_pres.events,
            nodes[k].last_error ? nodes[k].last_error.message().c_str() : "");
        last_boot[k] = nodes[k].boot;
      }
    }
    if (res.bus_up && !all_op) {
      all_op = true;
      all_op_at = woke;
      std::printf("EVENT t=%.3f all-operational\n", t_s);
      measure_from = woke + static_cast<int64_t>(o.warmup_s * 1e9);
    } else if (!res.bus_up && all_op) {
      all_op = false;
      std::printf("EVENT t=%.3f not-all-operational\n", t_s);
    }
    if (!measuring && measure_from != 0 && woke >= measure_from && measure_until == 0) {
      measuring = true;
      link.measuring = true;
      loss_totals(fired_at_start, events_at_start);
      for (const pl::CnStatus& st : bus->managing_node().nodes()) resets_at_start += st.resets;
      prev_fired = fired_at_start;
      prev_events = events_at_start;
      measure_until = o.duration_s > 0 ? woke + static_cast<int64_t>(o.duration_s * 1e9) : 0;
      std::printf("EVENT t=%.3f measuring\n", t_s);
    }
    if (measure_until != 0 && woke >= measure_until) break;
    if (!all_op && all_op_at == 0 && woke - start > static_cast<int64_t>(o.boot_timeout_s * 1e9)) {
      std::printf("EVENT t=%.3f boot-timeout\n", t_s);
      exit_code = 4;
      break;
    }

    // Identification read-back through SDO once operational: proves the SDO path end to end.
    if (all_op && !readback_sent && !config.axes.empty()) {
      ds1928::RegisterRequest rq;
      rq.tag = 1;
      rq.axis = 0;
      rq.reg = ds1928::reg::kEnDatMode;
      rq.size = 1;
      readback_sent = bus->submit(rq);
    }
    ds1928::RegisterResult rr;
    while (bus->poll(rr)) {
      // A read that failed (SDO timeout or abort: the CN was reset meanwhile, e.g. after a
      // stall of this machine beyond the loss-of-PRes ride-through) is asked again once the CN
      // is operational again, up to 3 times; a wrong value is never retried.
      if (rr.tag == 1 && !readback_done && rr.error && ++readback_failures < 3) {
        std::printf("EVENT t=%.3f sdo-readback-retry error=\"%s\"\n", t_s,
                    rr.error.message().c_str());
        readback_sent = false;
        continue;
      }
      if (rr.tag == 1 && !readback_done) {
        readback_done = true;
        const unsigned want = config.axes[0].module.endat_mode();
        std::printf("EVENT t=%.3f sdo-readback EnDatMode=0x%02x expected=0x%02x %s%s\n", t_s,
                    rr.value, want, rr.error ? rr.error.message().c_str() : "",
                    !rr.error && rr.value == want ? "ok" : "MISMATCH");
      }
    }

    // What would be published: positions against the simulated motion, NetTime stamps.
    // Stamps are mapped as the daemon maps them: through the bus' NetTimeRef (the SoC's send
    // instant ↔ its RelativeTime). The CN anchors its NetTime at the SoC's arrival, so a mapped
    // stamp is early by the SoC's transit from the bus' clock read to the CN's arrival stamp:
    // the residual W up to the socket (NETTIME line, ≈ 1 µs) plus the kernel's way to the peer.
    // That way runs through softirq processing, which a machine stall (or a loaded ksoftirqd)
    // delays by up to milliseconds, invisibly to the MN. So for 8 cycles after a stall — seen
    // as the MN thread waking late or the SoC's send call returning late — the checks allow the
    // stall's size; otherwise they allow 20 µs.
    const ds1928::NetTimeRef ref = res.net_time;
    int64_t stall = woke - next;
    if (ref.valid && link.soc_sent_ns != 0 && link.soc_sent_ns >= next) {
      if (measuring) ref_error.add(link.soc_sent_ns - ref.monotonic_ns);
      stall = std::max(stall, link.soc_send_done_ns - ref.monotonic_ns);
    }
    stall_window[index % stall_window.size()] = stall > 20'000 ? stall : 0;
    int64_t max_delay = 0;
    for (int64_t w : stall_window) max_delay = std::max(max_delay, w);
    for (std::size_t i = 0; i < axes.size(); ++i) {
      AxisCheck& c = checks[i];
      const ds1928::AxisSample s = ds1928::decode_axis(axes[i], c.params, ref, c.decode);
      if (s.stamp_too_old) ++old_stamps;
      if (!s.fresh) {
        if (!res.bus_up) c.have_prev = false;
        continue;
      }
      ++fresh;
      // Bounds against real instants, not the nominal cycle start: a woken-late cycle thread
      // sends its SoC late, and the stamps are (correctly) that late too. A stamp cannot be
      // after the exchange returned, nor older than 10 ms before the SoC.
      if (s.time_source != ds1928::TimeSource::NetTime || s.pos_time_ns > exchanged + 1000 ||
          s.pos_time_ns < ref.monotonic_ns - 10'000'000 - max_delay) {
        if (++bad_stamp <= 5)
          std::printf("EVENT t=%.3f axis=%zu bad-stamp pos_time=%u mapped=%+.1fus\n", t_s, i,
                      s.pos_time_raw, static_cast<double>(s.pos_time_ns - next) / 1000.0);
        continue;
      }
      const double pos = static_cast<double>(s.periods) + s.fraction / 65536.0;
      if (pos != 0.0) ++moving;
      if (o.check_positions && !std::isnan(c.velocity) && c.have_prev) {
        const double dt = static_cast<double>(s.pos_time_ns - c.prev_time) / 1e9;
        const double expected = c.velocity * dt;
        const double slack_s = 20e-6 + static_cast<double>(max_delay) * 1e-9;
        const double tolerance = 0.01 + std::fabs(c.velocity) * slack_s;
        // A late PRes taken for the next cycle's may even map before the previous sample.
        if (dt < -slack_s || std::fabs((pos - c.prev_pos) - expected) > tolerance) {
          if (++wrong <= 5)
            std::printf(
                "EVENT t=%.3f axis=%zu wrong-position pos=%.5f prev=%.5f dt=%.6f "
                "expected_delta=%.5f\n",
                t_s, i, pos, c.prev_pos, dt, expected);
        }
      }
      c.have_prev = true;
      c.prev_pos = pos;
      c.prev_time = s.pos_time_ns;
    }

    ++index;
    next += period_ns;
    const int64_t after = ds1928::rt::now_ns();
    if (measuring) work.add(after - woke);
    if (after > next) {
      // Overrun: skip the missed cycles instead of bursting to catch up.
      const int64_t missed = (after - next) / period_ns + 1;
      overruns += static_cast<uint64_t>(missed);
      if (measuring) {
        ++measured_overruns;
        measured_skipped += static_cast<uint64_t>(missed);
      }
      next += missed * period_ns;
      index += static_cast<uint64_t>(missed);
    }
  }

  uint32_t fired = 0, events = 0;
  loss_totals(fired, events);
  uint32_t boots = 0, resets = 0, stale = 0;
  for (const pl::CnStatus& st : bus->managing_node().nodes()) {
    boots += st.boots;
    resets += st.resets;
    stale += st.stale_pres_dropped;
  }
  // Where each node's process image came from, and how many objects its mapping has.
  for (const pl::CnStatus& st : bus->managing_node().nodes())
    std::printf("IMAGE node=%u source=%s tpdo=%zu rpdo=%zu refused=\"%s\"\n", st.node,
                std::string(pl::to_string(st.image_source)).c_str(),
                bus->managing_node().mapped_objects(st.node, true).size(),
                bus->managing_node().mapped_objects(st.node, false).size(),
                st.image_refusal.data());
  const pl::MnCounters& mc = bus->managing_node().counters();
  std::printf(
      "RESULT period_us=%u nodes=%zu cycles=%llu measured_cycles=%llu measured_skipped=%llu "
      "all_operational=%d "
      "boots=%u resets=%u loss_of_pres_events=%u loss_threshold_fired=%u "
      "measured_loss_events=%u measured_threshold_fired=%u overruns=%llu "
      "cycle_time_exceeded=%u invalid_frames=%u short_frames=%u unexpected_frames=%u "
      "async_timeouts=%u "
      "async_invites_unused=%u stale_pres_dropped=%u "
      "fresh=%llu moving=%llu wrong_positions=%llu bad_stamps=%llu old_stamps=%llu\n",
      config.cycle.period_us, config.powerlink.nodes.size(),
      static_cast<unsigned long long>(cycles), static_cast<unsigned long long>(measured_cycles),
      static_cast<unsigned long long>(measured_skipped), all_op ? 1 : 0, boots, resets, events,
      fired, measuring ? events - events_at_start : 0, measuring ? fired - fired_at_start : 0,
      static_cast<unsigned long long>(overruns), mc.cycle_time_exceeded.events, mc.invalid_frames,
      mc.short_frames, mc.unexpected_frames, mc.async_timeouts, mc.async_invites_unused, stale,
      static_cast<unsigned long long>(fresh), static_cast<unsigned long long>(moving),
      static_cast<unsigned long long>(wrong), static_cast<unsigned long long>(bad_stamp),
      static_cast<unsigned long long>(old_stamps));
  std::printf(
      "STALLS mn_wake_later_than_pres_timeout=%llu losses_after_stall=%llu "
      "losses_other=%llu late_pres=%llu fired_after_stall=%llu fired_other=%llu\n",
      static_cast<unsigned long long>(stalls), static_cast<unsigned long long>(losses_after_stall),
      static_cast<unsigned long long>(losses_other),
      static_cast<unsigned long long>(link.late_pres),
      static_cast<unsigned long long>(fired_after_stall),
      static_cast<unsigned long long>(fired_other));
  std::printf(
      "JITTER soc_to_soc_deviation_us p50=%.1f p99=%.1f max=%.1f (n=%llu, max interval %.1f us)\n",
      link.soc_jitter().percentile_us(0.5), link.soc_jitter().percentile_us(0.99),
      link.soc_jitter().max_us(), static_cast<unsigned long long>(link.soc_jitter().count()),
      static_cast<double>(link.soc_interval_max_ns()) / 1000.0);
  std::printf("LATENCY preq_to_pres_us p50=%.1f p99=%.1f max=%.1f (n=%llu)\n",
              link.latency().percentile_us(0.5), link.latency().percentile_us(0.99),
              link.latency().max_us(), static_cast<unsigned long long>(link.latency().count()));
  std::printf("WAKE latency_us p50=%.1f p99=%.1f max=%.1f\n", wake.percentile_us(0.5),
              wake.percentile_us(0.99), wake.max_us());
  // Overruns here: measured cycles whose work ended after the next cycle's start (each once,
  // however many slots it cost); resets: CN resets by the MN in the measured window.
  std::printf(
      "WORK cycle_work_us p50=%.1f p99=%.1f max=%.1f measured_overruns=%llu "
      "measured_resets=%u\n",
      work.percentile_us(0.5), work.percentile_us(0.99), work.max_us(),
      static_cast<unsigned long long>(measured_overruns),
      resets - std::min(resets, resets_at_start));
  std::printf(
      "NETTIME soc_send_delay_us p50=%.1f p99=%.1f max=%.1f (SoC send instant vs "
      "NetTimeRef.monotonic_ns)\n",
      ref_error.percentile_us(0.5), ref_error.percentile_us(0.99), ref_error.max_us());
  bus->stop();
  if (dma_fd >= 0) close(dma_fd);
  if (exit_code == 0 && (wrong != 0 || bad_stamp != 0)) exit_code = 3;
  return exit_code;
}
