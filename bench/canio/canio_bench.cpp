// CAN-I/O bus figures:
//  1. The bit budget: bits on the wire per cycle (nominal and with worst-case bit stuffing) for
//     1, 2, 4, 8 X20DS1928 modules (2 input objects + 1 output object of 8 bytes each) at
//     500 kbit/s and 1 Mbit/s, with and without SYNC, and the shortest cycle the bus allows.
//     Pure arithmetic (src/can/bit_budget.hpp): the physical limit any master is held to.
//  2. What a master/node pair sustains per cycle over the virtual CAN bus (the test transport):
//     the master sends SYNC + N output objects, the node answers with 2N input objects, the master
//     waits for all of them; one cycle after another, as fast as they go. Two threads in one
//     process, and two processes over the shared-memory bus. Baseline from the same run: the same
//     exchange over a Unix SOCK_SEQPACKET socket pair (one datagram per frame), the kernel IPC a
//     stand-in transport would otherwise use.
//
//   canio_bench [--cycles N] [--quick]
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "can/bit_budget.hpp"
#include "can/virtual_bus.hpp"

using namespace ds1928::canio;

namespace {

int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void print_budget() {
  std::printf(
      "Bits on the wire per cycle (classic CAN 2.0A, 8-byte objects: 2 in + 1 out per "
      "module; SYNC = 0-byte frame)\n");
  std::printf("%-9s %7s %5s %6s %12s %12s %14s %14s %11s\n", "bitrate", "modules", "sync", "frames",
              "bits nominal", "bits worst", "time nominal", "shortest cycle", "max rate");
  for (uint32_t bitrate : {500'000u, 1'000'000u}) {
    for (bool sync : {false, true}) {
      for (uint32_t modules : {1u, 2u, 4u, 8u}) {
        CycleLoad load;
        load.modules = modules;
        load.bitrate = bitrate;
        load.sync = sync;
        const CycleBudget b = cycle_budget(load);
        std::printf("%-9s %7u %5s %6u %12llu %12llu %11.1f us %11.1f us %8.0f Hz\n",
                    bitrate == 500'000 ? "500k" : "1M", modules, sync ? "yes" : "no", b.frames,
                    static_cast<unsigned long long>(b.bits_nominal),
                    static_cast<unsigned long long>(b.bits_worst_case), b.time_nominal_ns / 1e3,
                    b.time_worst_case_ns / 1e3, 1e9 / static_cast<double>(b.time_worst_case_ns));
      }
    }
  }
  std::printf("(one 8-byte frame: %u bits nominal, %u worst case; SYNC: %u / %u)\n\n",
              frame_bits(8).nominal, frame_bits(8).worst_case, frame_bits(0).nominal,
              frame_bits(0).worst_case);
}

struct Figures {
  double cycles_per_s = 0;
  double p50_us = 0, p99_us = 0, max_us = 0;
  uint64_t incomplete = 0;
};

Figures summarize(std::vector<int64_t>& t, int64_t total_ns, uint64_t incomplete) {
  Figures f;
  std::sort(t.begin(), t.end());
  f.cycles_per_s = static_cast<double>(t.size()) * 1e9 / static_cast<double>(total_ns);
  f.p50_us = t[t.size() / 2] / 1e3;
  f.p99_us = t[t.size() * 99 / 100] / 1e3;
  f.max_us = t.back() / 1e3;
  f.incomplete = incomplete;
  return f;
}

constexpr uint32_t kSync = 0x080;
uint32_t in_id(uint32_t module, uint32_t object) {
  return 0x181 + 0x100 * object + module;
}
uint32_t out_id(uint32_t module) {
  return 0x201 + module;
}

CanFrame object(uint32_t id, uint32_t cycle) {
  uint8_t b[8] = {};
  std::memcpy(b, &cycle, sizeof cycle);
  return make_standard_frame(id, b);
}

// The node: on SYNC, answers with 2N input objects carrying the cycle number; consumes outputs.
void run_node(CanPort& port, uint32_t modules, uint32_t cycles) {
  std::array<CanFrame, 32> buf;
  for (uint32_t done = 0; done < cycles;) {
    auto r = port.receive(buf, now_ns() + 5'000'000'000);
    if (r.count == 0) return;  // master gone
    for (std::size_t i = 0; i < r.count; ++i) {
      if (buf[i].id != kSync) continue;
      uint32_t cycle = 0;
      std::memcpy(&cycle, buf[i].data.data(), sizeof cycle);
      for (uint32_t m = 0; m < modules; ++m)
        for (uint32_t o = 0; o < 2; ++o) (void)port.send(object(in_id(m, o), cycle));
      ++done;
    }
  }
}

// The master: SYNC + outputs, then waits for all inputs of this cycle (bounded).
Figures run_master(CanPort& port, uint32_t modules, uint32_t cycles) {
  std::vector<int64_t> times;
  times.reserve(cycles);
  std::array<CanFrame, 32> buf;
  uint64_t incomplete = 0;
  const int64_t start = now_ns();
  for (uint32_t c = 0; c < cycles; ++c) {
    const int64_t t0 = now_ns();
    (void)port.send(object(kSync, c));
    for (uint32_t m = 0; m < modules; ++m) (void)port.send(object(out_id(m), c));
    uint32_t got = 0;
    const int64_t deadline = t0 + 1'000'000'000;
    while (got < 2 * modules) {
      auto r = port.receive(buf, deadline);
      if (r.count == 0) break;
      for (std::size_t i = 0; i < r.count; ++i) {
        uint32_t cycle = 0;
        std::memcpy(&cycle, buf[i].data.data(), sizeof cycle);
        got += cycle == c ? 1 : 0;
      }
    }
    if (got < 2 * modules) ++incomplete;
    times.push_back(now_ns() - t0);
  }
  return summarize(times, now_ns() - start, incomplete);
}

// Baseline transport: a SOCK_SEQPACKET pair, one datagram per CAN frame.
class SocketPairPort final : public CanPort {
 public:
  explicit SocketPairPort(int fd) : fd_(fd) {}
  ~SocketPairPort() override { close(fd_); }
  SendResult send(const CanFrame& f) noexcept override {
    return ::send(fd_, &f, sizeof f, MSG_DONTWAIT) == sizeof f
               ? SendResult{}
               : SendResult{SendStatus::QueueFull, errno};
  }
  ReceiveResult receive(std::span<CanFrame> out, int64_t deadline_ns) noexcept override {
    std::size_t n = 0;
    while (n < out.size()) {
      const bool block = n == 0;
      if (block) {
        const int64_t wait = deadline_ns - now_ns();
        if (wait <= 0) return {0, {}};
        timeval tv{static_cast<time_t>(wait / 1'000'000'000),
                   static_cast<suseconds_t>(wait % 1'000'000'000 / 1000)};
        setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
      }
      if (recv(fd_, &out[n], sizeof(CanFrame), block ? 0 : MSG_DONTWAIT) != sizeof(CanFrame)) break;
      ++n;
    }
    return {n, {}};
  }
  CanState state() const noexcept override { return CanState::ErrorActive; }
  CanPortCounters counters() const noexcept override { return {}; }
  std::error_code set_filters(std::span<const CanIdFilter>) noexcept override { return {}; }
  std::error_code set_error_mask(uint32_t) noexcept override { return {}; }
  ds1928::Result<CanInterfaceInfo> query_interface() noexcept override {
    return CanInterfaceInfo{};
  }
  std::string_view name() const noexcept override { return "socketpair"; }

 private:
  int fd_;
};

void print_row(const char* transport, uint32_t modules, const Figures& f, double baseline_rate) {
  std::printf("%-26s %7u %12.0f %9.1f %9.1f %9.1f %10llu", transport, modules, f.cycles_per_s,
              f.p50_us, f.p99_us, f.max_us, static_cast<unsigned long long>(f.incomplete));
  if (baseline_rate > 0) std::printf("   x%.2f", f.cycles_per_s / baseline_rate);
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  uint32_t cycles = 20'000;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) cycles = 2'000;
    if (std::strcmp(argv[i], "--cycles") == 0 && i + 1 < argc)
      cycles = static_cast<uint32_t>(std::atoi(argv[++i]));
  }
  print_budget();

  std::printf("Master/node exchange per cycle (SYNC + N outputs out, 2N inputs back), %u cycles\n",
              cycles);
  std::printf("%-26s %7s %12s %9s %9s %9s %10s   %s\n", "transport", "modules", "cycles/s",
              "p50 us", "p99 us", "max us", "incomplete", "vs baseline");
  for (uint32_t modules : {1u, 2u, 4u, 8u}) {
    // Baseline: Unix socket pair between two threads.
    int sv[2];
    if (socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0) return 1;
    Figures base;
    {
      SocketPairPort master(sv[0]), node(sv[1]);
      std::thread t([&] { run_node(node, modules, cycles); });
      base = run_master(master, modules, cycles);
      t.join();
    }
    print_row("baseline: unix seqpacket", modules, base, 0);

    // Virtual bus, two threads.
    {
      auto bus = VirtualCanBus::create_local();
      auto master = bus->open_port(), node = bus->open_port();
      if (!master || !node) return 1;
      std::thread t([&] { run_node(**node, modules, cycles); });
      const Figures f = run_master(**master, modules, cycles);
      t.join();
      print_row("virtual bus, threads", modules, f, base.cycles_per_s);
    }

    // Virtual bus in shared memory, two processes.
    {
      const std::string name = "bench-" + std::to_string(getpid());
      auto bus = VirtualCanBus::open_shared(name, {}, true);
      if (!bus) return 1;
      auto master = (*bus)->open_port();
      if (!master) return 1;
      const pid_t child = fork();
      if (child == 0) {
        auto b = VirtualCanBus::open_shared(name);
        if (!b) _exit(2);
        auto node = (*b)->open_port();
        if (!node) _exit(3);
        (void)(*node)->send(object(0x700, 0));  // ready
        run_node(**node, modules, cycles);
        _exit(0);
      }
      std::array<CanFrame, 4> ready;
      if ((*master)->receive(ready, now_ns() + 10'000'000'000).count != 1) return 1;
      const Figures f = run_master(**master, modules, cycles);
      int status = 0;
      waitpid(child, &status, 0);
      print_row("virtual bus, processes", modules, f, base.cycles_per_s);
    }
  }
  std::printf(
      "\nThe virtual bus has no bit timing: these rates are what the transport itself "
      "costs, far above what a real CAN bus allows (table above).\n");
  return 0;
}
