// What the CAN-I/O bus driver sustains on the virtual bus, next to the bus' physical limit:
//  1. shortest cycle: CanioBus (daemon side) and a simulated CAN-I/O node on its own thread over
//     the in-process virtual bus, real clock, absolute-time pacing; for each period, the cycles
//     whose exchange overran the period and the samples that were not whole (half/missing). The
//     physical limit of a real 500 kbit/s bus (bit_budget) is printed beside it.
//  2. EnDat read-parameter latency in bus cycles through Flatstream at MTU 3, 4, 5 (stepped, fake
//     clock: cycles, not time), next to the lower bound of the MTU: the request's and the reply's
//     sequences, one per cycle each way.
// Not part of ctest: build/bench/canio/canio_driver_bench [--cycles N].
#include <time.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "../../tests/canio_bus/rig.hpp"
#include "canio/bit_budget.hpp"
#include "endat/command.hpp"
#include "flatstream/channel.hpp"

using namespace ds1928;

namespace {

int64_t mono() {
  return test::Rig::monotonic();
}

void sleep_until(int64_t t) {
  timespec ts{static_cast<time_t>(t / 1'000'000'000), static_cast<long>(t % 1'000'000'000)};
  clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

struct Sustained {
  uint64_t cycles = 0, overruns = 0, not_whole = 0;
};

Sustained run_period(uint32_t period_us, uint64_t cycles) {
  DaemonConfig c = test::canio_config(1, period_us);
  c.canio.response_timeout_us = period_us / 2;
  test::Rig rig(c, false, true);
  (void)rig.canio->start();
  Sustained s;
  int64_t next = mono() + 1'000'000;
  for (uint64_t i = 0; i < cycles; ++i) {
    sleep_until(next);
    (void)rig.cycle(i);
    if (mono() > next + static_cast<int64_t>(period_us) * 1000) ++s.overruns;
    next += static_cast<int64_t>(period_us) * 1000;
    if (i >= 10 && !rig.io[0].inputs_fresh) ++s.not_whole;  // first cycles: node thread starting
  }
  s.cycles = cycles;
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

}  // namespace

int main(int argc, char** argv) {
  uint64_t cycles = 5000;
  for (int i = 1; i + 1 < argc; ++i)
    if (std::strcmp(argv[i], "--cycles") == 0) cycles = std::stoull(argv[i + 1]);

  canio::CycleLoad load;
  load.modules = 1;
  load.sync = true;
  load.bitrate = 500'000;
  const auto limit500 = canio::cycle_budget(load);
  load.bitrate = 1'000'000;
  const auto limit1m = canio::cycle_budget(load);
  std::printf(
      "1 module + SYNC, physical limit (worst-case stuffing): %lld µs at 500 kbit/s, "
      "%lld µs at 1 Mbit/s\n",
      static_cast<long long>(limit500.time_worst_case_ns / 1000),
      static_cast<long long>(limit1m.time_worst_case_ns / 1000));
  std::printf("| period µs | cycles | overruns | samples not whole |\n|---|---|---|---|\n");
  uint32_t shortest = 0;
  for (uint32_t p : {2000u, 1000u, 500u, 250u, 200u, 100u}) {
    const Sustained s = run_period(p, cycles);
    std::printf("| %u | %llu | %llu | %llu |\n", p, static_cast<unsigned long long>(s.cycles),
                static_cast<unsigned long long>(s.overruns),
                static_cast<unsigned long long>(s.not_whole));
    if (s.overruns == 0 && s.not_whole == 0) shortest = p;
  }
  std::printf(
      "shortest period sustained on the virtual bus without overrun or half sample: %u "
      "µs\n\n",
      shortest);
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
