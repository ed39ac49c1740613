// Request/response round trip over a raw POWERLINK link for each receive strategy of RawLink
// (TPACKET_V2 ring polled on its status word, recv(MSG_DONTWAIT) polling, blocking ppoll+recv).
// One process answers PReq-shaped frames with PRes-shaped frames ("echo"), the other sends one
// request per period and measures until the answer arrives ("ping"). run_rx_latency.sh puts the
// two in network namespaces joined by a veth pair and runs every mode.
#include <fcntl.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <vector>

#include "core/clock.hpp"
#include "powerlink/raw_link.hpp"

namespace pl = ds1928::powerlink;

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) {
  g_stop.store(true);
}

constexpr uint8_t kMnNode = 240;

void try_realtime(int prio, int cpu) {
  if (cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) != 0) std::perror("sched_setaffinity");
  }
  // Deep C-states add tens of µs to every wake-up; hold the fd open for the process' life.
  static const int dma_fd = [] {
    const int fd = ::open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
    if (fd >= 0) {
      const int32_t zero = 0;
      if (::write(fd, &zero, sizeof zero) != sizeof zero) std::perror("cpu_dma_latency");
    }
    return fd;
  }();
  (void)dma_fd;
  if (prio > 0) {
    sched_param sp{};
    sp.sched_priority = prio;
    if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) std::perror("SCHED_FIFO (continuing)");
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) std::perror("mlockall (continuing)");
  }
}

// PReq (MN → CN) or PRes (CN → all) with `payload` bytes; enough of the layout for the peer to
// recognise it, the codec proper is tested elsewhere.
std::size_t make_frame(uint8_t* f, const pl::MacAddress& src, bool preq, uint8_t node,
                       std::size_t payload, uint32_t seq) {
  const std::size_t len = std::max<std::size_t>(60, 24 + payload);
  std::memset(f, 0, len);
  const pl::MacAddress dst =
      preq ? pl::MacAddress{0xff, 0xff, 0xff, 0xff, 0xff, 0xff} : pl::kMacPRes;
  std::memcpy(f, dst.data(), 6);
  std::memcpy(f + 6, src.data(), 6);
  f[12] = 0x88;
  f[13] = 0xAB;
  f[14] = preq ? 0x03 : 0x04;
  f[15] = preq ? node : 255;
  f[16] = preq ? kMnNode : node;
  pl::store_le16(f + 22, static_cast<uint16_t>(payload));
  if (payload >= 4) pl::store_le32(f + 24, seq);
  return len;
}

pl::RxMode parse_mode(const std::string& s) {
  if (s == "busy-poll") return pl::RxMode::BusyPoll;
  if (s == "blocking") return pl::RxMode::Blocking;
  return pl::RxMode::Ring;
}

// A SCHED_FIFO task that spins all the time is throttled by the kernel (sched_rt_runtime_us)
// for tens of ms per second; like the simulated CN, the echo sleeps until `guard_us` before the
// next request is due and spins only from there.
int run_echo(pl::RawLink& link, uint8_t node, uint32_t period_us, uint32_t guard_us) {
  std::array<uint8_t, 1514> rx{};
  std::array<uint8_t, 1514> tx{};
  uint64_t answered = 0;
  int64_t last_request = 0;
  const bool predictive = link.rx_mode() != pl::RxMode::Blocking && guard_us < period_us;
  while (!g_stop.load(std::memory_order_relaxed)) {
    int64_t now = ds1928::rt::now_ns();
    if (predictive) {
      const int64_t wake = last_request + (static_cast<int64_t>(period_us) - guard_us) * 1000;
      if (wake > now) {
        const timespec ts{static_cast<time_t>(wake / 1'000'000'000),
                          static_cast<long>(wake % 1'000'000'000)};
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
      } else if (now - last_request > 4LL * period_us * 1000) {
        // Lost the rhythm (start, pause): block until the next request arrives.
        if (!link.wait_readable(now + 100'000'000)) continue;
      }
      now = ds1928::rt::now_ns();
    }
    const auto r = link.receive(rx, now + (predictive ? 2LL * guard_us * 1000 : 100'000'000));
    if (r.error) {
      std::fprintf(stderr, "echo: receive: %s\n", r.error.message().c_str());
      continue;
    }
    const std::size_t n = r.length;
    if (n == 0) continue;
    if (n < 24 || rx[14] != 0x03 || rx[15] != node) continue;
    last_request = ds1928::rt::now_ns();
    const std::size_t payload = pl::load_le16(rx.data() + 22);
    const uint32_t seq = payload >= 4 ? pl::load_le32(rx.data() + 24) : 0;
    const std::size_t len = make_frame(tx.data(), link.mac(), false, node, payload, seq);
    if (auto ec = link.send({tx.data(), len})) {
      std::fprintf(stderr, "echo: send: %s\n", ec.message().c_str());
    }
    ++answered;
  }
  std::fprintf(stderr, "echo: answered %llu\n", static_cast<unsigned long long>(answered));
  return 0;
}

int run_ping(pl::RawLink& link, uint8_t node, uint32_t count, uint32_t period_us,
             std::size_t payload, const std::string& label) {
  std::array<uint8_t, 1514> rx{};
  std::array<uint8_t, 1514> tx{};
  std::vector<int64_t> rtt;
  rtt.reserve(count);
  uint32_t lost = 0;
  timespec next{};
  clock_gettime(CLOCK_MONOTONIC, &next);
  // Warm-up: the first exchanges fault in pages and caches.
  for (uint32_t i = 0; i < count + 100 && !g_stop.load(); ++i) {
    next.tv_nsec += static_cast<long>(period_us) * 1000;
    while (next.tv_nsec >= 1'000'000'000) {
      next.tv_nsec -= 1'000'000'000;
      ++next.tv_sec;
    }
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    const std::size_t len = make_frame(tx.data(), link.mac(), true, node, payload, i);
    const int64_t t0 = ds1928::rt::now_ns();
    if (auto ec = link.send({tx.data(), len})) {
      std::fprintf(stderr, "ping: send: %s\n", ec.message().c_str());
      ++lost;
      continue;
    }
    const int64_t deadline = t0 + 1'000'000;
    bool got = false;
    while (!got) {
      const auto r = link.receive(rx, deadline);
      if (r.error || r.length == 0) break;
      if (r.length >= 28 && rx[14] == 0x04 && rx[16] == node &&
          pl::load_le32(rx.data() + 24) == i) {
        got = true;
        if (i >= 100) rtt.push_back(r.rx_time_ns - t0);
      }
    }
    if (!got && i >= 100) ++lost;
  }
  std::sort(rtt.begin(), rtt.end());
  auto pct = [&](double p) -> double {
    if (rtt.empty()) return 0.0;
    const auto idx = static_cast<std::size_t>(p * static_cast<double>(rtt.size() - 1));
    return static_cast<double>(rtt[idx]) / 1000.0;
  };
  std::printf("%-10s n=%zu lost=%u  rtt_us median=%.1f p90=%.1f p99=%.1f max=%.1f\n", label.c_str(),
              rtt.size(), lost, pct(0.5), pct(0.9), pct(0.99), pct(1.0));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"POWERLINK raw-link request/response latency"};
  std::string role;
  std::string iface;
  std::string mode = "ring";
  int node = 1;
  uint32_t count = 20000;
  uint32_t period_us = 200;
  std::size_t payload = 36;
  int prio = 0;
  int cpu = -1;
  uint32_t guard_us = 60;
  app.add_option("role", role, "echo | ping")->required()->check(CLI::IsMember({"echo", "ping"}));
  app.add_option("--iface", iface, "interface")->required();
  app.add_option("--mode", mode, "ring | busy-poll | blocking")
      ->check(CLI::IsMember({"ring", "busy-poll", "blocking"}));
  app.add_option("--node", node, "CN node id")->check(CLI::Range(1, 239));
  app.add_option("--count", count, "requests (ping)");
  app.add_option("--period-us", period_us, "request period (ping)");
  app.add_option("--payload", payload, "PReq/PRes payload bytes")->check(CLI::Range(0, 1490));
  app.add_option("--guard-us", guard_us, "echo: start polling this long before a request is due");
  app.add_option("--rt", prio, "SCHED_FIFO priority (0 = normal)");
  app.add_option("--cpu", cpu, "pin to this CPU");
  CLI11_PARSE(app, argc, argv);

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try_realtime(prio, cpu);

  pl::RawLink link;
  pl::RawLinkOptions options;
  options.interface = iface;
  options.rx_mode = parse_mode(mode);
  if (auto ec = link.open(options)) {
    std::fprintf(stderr, "open %s: %s\n", iface.c_str(), ec.message().c_str());
    return 2;
  }
  if (role == "echo") return run_echo(link, static_cast<uint8_t>(node), period_us, guard_us);
  return run_ping(link, static_cast<uint8_t>(node), count, period_us, payload, mode);
}
