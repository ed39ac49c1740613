// EnDat command latency through the daemon's path (EnDatService → CycleWork's Flatstream tunnel
// → simulated module → EnDat bridge → simulated encoder and back), in bus cycles and wall time,
// for a read-param and for the full identification read over Flatstream (44 words), at
// MTU 5 (CAN-I/O) and MTU 15 (POWERLINK) with Forward 1 and 7, next to the minimum the MTU allows.
//
// Minimum (printed next to each figure): sequences per message = ceil((bytes + control bytes) /
// MTU) in the large-segment + MultiSegmentMTU layout; a message of S sequences with Forward F
// over a bus whose ack returns R cycles after a sequence is written needs
// t_i = max(t_{i-1} + 1, t_{i-F} + R) cycles, last sequence at t_S; the in-process simulated bus
// has R = 1 (the module answers in the same exchange), X2X R = 5. Add one cycle for the cycle
// thread to take the request from the normal thread and the encoder's processing time (the
// simulated encoder: 2 ms selection + 2 ms read = 4 ms).
//
//   build/bench/endat/endat_bench [--reps N] [--period-us P]
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <boost/asio/post.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <future>
#include <string>
#include <thread>
#include <vector>

#include "cycle_work.hpp"
#include "endat/ident.hpp"
#include "endat_service.hpp"
#include "register_client.hpp"
#include "shm/publisher.hpp"
#include "sim/simulated_bus.hpp"

using namespace ds1928;
using Clock = std::chrono::steady_clock;

namespace {

// Cycle of the last sequence of a message of `s` sequences (first written in cycle 1).
unsigned transfer_cycles(unsigned s, unsigned forward, unsigned round_trip) {
  std::vector<unsigned> t(s + 1, 0);
  for (unsigned i = 1; i <= s; ++i) {
    unsigned at = i == 1 ? 1 : t[i - 1] + 1;
    if (i > forward) at = std::max(at, t[i - forward] + round_trip);
    t[i] = at;
  }
  return t[s];
}

unsigned sequences(unsigned bytes, unsigned mtu) {
  // Large segments + MultiSegmentMTU: one control byte per segment of up to 63 bytes.
  const unsigned total = bytes + (bytes + 62) / 63;
  return (total + mtu - 1) / mtu;
}

struct Setup {
  uint8_t mtu;
  uint8_t forward;
};

class Bench {
 public:
  Bench(Setup s, uint32_t period_us) : period_us_(period_us) {
    config_.cycle.period_us = period_us;
    AxisConfig axis;
    axis.module.output_mtu = s.mtu;
    axis.module.input_mtu = s.mtu;
    axis.module.flatstream_mode = 3;
    axis.module.forward = s.forward;
    axis.function_model = s.mtu <= 5 ? FunctionModel::BusController : FunctionModel::Standard;
    config_.axes.push_back(axis);
    config_.shm.name = "/ds1928-endat-bench-" + std::to_string(getpid());
    bus_ = std::make_unique<sim::SimulatedBus>(config_.axes, config_.simulated);
    if (auto ec = bus_->start()) throw std::runtime_error(ec.message());
    if (auto ec = publisher_.open(config_.shm, 1, uint64_t{period_us} * 1000))
      throw std::runtime_error(ec.message());
    work_ = std::make_unique<CycleWork>(config_, *bus_, publisher_);
    registers_ = std::make_unique<RegisterClient>(io_, *bus_);
    service_ = std::make_unique<EnDatService>(io_, *work_, *registers_, config_);
    cycle_ = std::thread([this] { loop(); });
    registers_->start(std::chrono::microseconds(period_us));
    service_->start();
    io_thread_ = std::thread([this] { io_.run(); });
    // Let the channels synchronise and the start-up identification finish.
    for (int i = 0; i < 500 && !run([this] { return service_->identification(0).has_value(); });
         ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ~Bench() {
    run([this] {
      service_->stop();
      registers_->stop();
    });
    guard_.reset();
    io_.stop();
    io_thread_.join();
    stop_ = true;
    cycle_.join();
    publisher_.close();
  }

  struct Sample {
    uint64_t cycles;
    double ms;
    bool ok;
  };
  // Runs one job and measures it from submission to completion.
  Sample job(EnDatService::JobKind kind, std::vector<endat::Request> steps) {
    std::promise<Sample> done;
    auto result = done.get_future();
    run([&] {
      const uint64_t c0 = work_->exchanges();
      const auto t0 = Clock::now();
      service_->submit(0, kind, steps, [&, c0, t0](const EnDatService::JobResult& r) {
        bool ok = !r.error;
        for (const auto& s : r.steps) ok = ok && !s.error;
        done.set_value({work_->exchanges() - c0,
                        std::chrono::duration<double, std::milli>(Clock::now() - t0).count(), ok});
      });
      return 0;
    });
    return result.get();
  }
  // Identification through the acyclic registers (what the daemon does first).
  double register_ident_ms() {
    std::promise<double> done;
    auto result = done.get_future();
    run([&] {
      const auto t0 = Clock::now();
      service_->refresh_identification(0, [&, t0](std::error_code) {
        done.set_value(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      });
      return 0;
    });
    return result.get();
  }

 private:
  template <class F>
  auto run(F f) -> decltype(f()) {
    std::packaged_task<decltype(f())()> task(std::move(f));
    auto r = task.get_future();
    boost::asio::post(io_, [&task] { task(); });
    return r.get();
  }
  void loop() {
    auto next = Clock::now();
    uint64_t index = 0;
    while (!stop_) {
      CycleContext ctx;
      ctx.index = index++;
      ctx.start_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(next.time_since_epoch()).count();
      ctx.woke_ns = ctx.start_ns;
      work_->run_cycle(ctx);
      next += std::chrono::microseconds(period_us_);
      std::this_thread::sleep_until(next);
    }
  }

  uint32_t period_us_;
  DaemonConfig config_;
  std::unique_ptr<sim::SimulatedBus> bus_;
  shm::Publisher publisher_;
  std::unique_ptr<CycleWork> work_;
  boost::asio::io_context io_;
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>> guard_{
      boost::asio::make_work_guard(io_)};
  std::unique_ptr<RegisterClient> registers_;
  std::unique_ptr<EnDatService> service_;
  std::thread cycle_;
  std::thread io_thread_;
  std::atomic<bool> stop_{false};
};

template <class T>
T median(std::vector<T> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  int reps = 21;
  uint32_t period_us = 1000;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--reps") && i + 1 < argc) reps = std::max(1, std::atoi(argv[++i]));
    if (!std::strcmp(argv[i], "--period-us") && i + 1 < argc)
      period_us = static_cast<uint32_t>(std::max(100, std::atoi(argv[++i])));
  }
  const double endat_read_ms = 4.0;  // simulated encoder: selection 2 ms + read 2 ms
  const unsigned endat_cycles =
      static_cast<unsigned>(std::ceil(endat_read_ms * 1000.0 / period_us));
  std::printf(
      "EnDat commands through the daemon path, bus cycle %u µs, simulated encoder "
      "(read = %.1f ms EnDat time), median of %d\n\n",
      period_us, endat_read_ms, reps);
  std::printf(
      "| MTU | Fwd | read-param cycles (min sim / X2X) | read-param wall ms (min) | "
      "ident 44 words cycles (min sim) | ident wall ms (min) | ident via registers ms |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  for (const Setup s : {Setup{5, 1}, Setup{5, 7}, Setup{15, 1}, Setup{15, 7}}) {
    Bench bench(s, period_us);
    const unsigned rq = sequences(3, s.mtu), rp = sequences(5, s.mtu);
    // +1: the cycle thread takes the request at the start of the next cycle.
    const unsigned min_sim =
        1 + transfer_cycles(rq, s.forward, 1) + endat_cycles + transfer_cycles(rp, s.forward, 1);
    const unsigned min_x2x = 1 + transfer_cycles(rq, s.forward, 5) + 2 + endat_cycles +
                             transfer_cycles(rp, s.forward, 5) + 2;  // + one-way delays
    std::vector<uint64_t> cycles;
    std::vector<double> ms;
    int failures = 0;
    for (int i = 0; i < reps; ++i) {
      const auto r = bench.job(EnDatService::JobKind::Single, {endat::Request::read(0xA9, 1)});
      cycles.push_back(r.cycles);
      ms.push_back(r.ms);
      failures += !r.ok;
    }
    std::vector<endat::Request> ident;
    for (unsigned w = 4; w < endat::kManufacturerWords; ++w)
      ident.push_back(
          endat::Request::read(endat::manufacturer_page_mrs(w), static_cast<uint8_t>(w % 16)));
    std::vector<uint64_t> icycles;
    std::vector<double> ims, regms;
    for (int i = 0; i < std::max(1, reps / 7); ++i) {
      const auto r = bench.job(EnDatService::JobKind::Sequence, ident);
      icycles.push_back(r.cycles);
      ims.push_back(r.ms);
      failures += !r.ok;
      regms.push_back(bench.register_ident_ms());
    }
    std::printf("| %u | %u | %llu (%u / %u) | %.2f (%.2f) | %llu (%u) | %.1f (%.1f) | %.1f |%s\n",
                s.mtu, s.forward, static_cast<unsigned long long>(median(cycles)), min_sim, min_x2x,
                median(ms), min_sim * period_us / 1000.0,
                static_cast<unsigned long long>(median(icycles)), 44 * min_sim, median(ims),
                44 * min_sim * period_us / 1000.0, median(regms), failures ? "  FAILURES" : "");
    std::fflush(stdout);
  }
  return 0;
}
