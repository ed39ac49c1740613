// The daemon's whole cycle (simulated bus exchange, decoding, Flatstream tunnels with EnDat
// traffic, acknowledgements, shared-memory publication) makes no heap allocation, takes no mutex
// and no page fault on the cycle thread, over 100 000 steady cycles, while the normal thread keeps
// feeding it requests and four shared-memory readers sleep in ds1928_shm_wait — woken by the
// publisher's wake-up thread, the cycle thread making no system call for them.
#include <unistd.h>

#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <thread>

#include "core/cycle_engine.hpp"
#include "cycle_proof.hpp"
#include "cycle_work.hpp"
#include "ds1928/shm.hpp"
#include "endat/command.hpp"
#include "shm/publisher.hpp"
#include "sim/simulated_bus.hpp"
#include "support/alloc_counter.hpp"
#include "support/wait.hpp"

using namespace ds1928;

namespace {

DaemonConfig four_axes(uint32_t period_us) {
  DaemonConfig c;
  c.cycle.period_us = period_us;
  c.cycle.hold_cpu_dma_latency = false;
  c.axes.resize(4);
  for (std::size_t i = 0; i < c.axes.size(); ++i) {
    c.axes[i].name = "axis" + std::to_string(i);
    c.axes[i].slot = static_cast<uint8_t>(i + 1);
    c.axes[i].module.forward = static_cast<uint8_t>(1 + 2 * i);  // 1, 3, 5, 7
    c.axes[i].module.flatstream_mode = static_cast<uint8_t>(i & 3);
  }
  c.axes[3].function_model = FunctionModel::BusController;
  c.axes[3].module.input_mtu = c.axes[3].module.output_mtu = 5;
  c.simulated.axes.resize(4);
  c.simulated.axes[1].profile = MotionProfile::Sine;
  c.shm.name = "/ds1928d-noalloc-" + std::to_string(::getpid());
  return c;
}

}  // namespace

TEST_CASE("the daemon's cycle work allocates nothing and locks no mutex in 100 000 cycles",
          "[daemon][rt]") {
  const DaemonConfig config = four_axes(100);
  sim::SimulatedBus bus(config.axes, config.simulated);
  REQUIRE_FALSE(bus.start());
  shm::Publisher publisher;
  REQUIRE_FALSE(publisher.open(config.shm, 4, 100'000));
  CycleWork work(config, bus, publisher);
  constexpr uint64_t kWarmup = 2000;
  constexpr uint64_t kCounted = 100'000;
  test::CountingTask task(work, kCounted, kWarmup);
  // Readers asleep throughout (factors 1, 1, 2 and 16), counting what they get.
  std::atomic<bool> readers_stop{false};
  std::array<std::atomic<uint64_t>, 4> got{};
  std::vector<std::thread> readers;
  for (uint32_t r = 0; r < 4; ++r) {
    readers.emplace_back([&, r] {
      const uint32_t every = std::array<uint32_t, 4>{1, 1, 2, 16}[r];
      ShmReader reader;
      if (reader.open(config.shm.name)) return;
      uint64_t seen = reader.wait_start();
      std::error_code ec;
      while (!readers_stop.load()) {
        if (reader.wait(seen, every, ds1928_shm_now_ns() + 200'000'000, ec) == ShmWait::Published)
          got[r].fetch_add(1);
      }
    });
  }
  struct StopReaders {
    std::atomic<bool>& stop;
    std::vector<std::thread>& threads;
    ~StopReaders() {
      stop = true;
      for (auto& t : threads) t.join();
    }
  } stop_readers{readers_stop, readers};
  // As the daemon places it: one below the cycle thread, on its CPU.
  (void)publisher.place_waker(config.cycle.rt_priority - 1, config.cycle.cpu);
  auto engine = std::make_unique<CycleEngine>(config.cycle, task);
  auto started = engine->start();
  REQUIRE(started);

  // The normal thread's traffic during the counted cycles: EnDat commands through every axis'
  // Flatstream tunnel, acknowledgements, acyclic register reads.
  const auto read =
      endat::encode_request(endat::Request::read(0xA1, 8), endat::CommandSet::EnDat22);
  REQUIRE(read);
  test::CycleTraffic traffic;
  // One round every 50 cycles (5 ms): the traffic per counted cycle does not depend on how the
  // scheduler shares the cores between this thread and the cycle thread.
  while (!task.done()) {
    traffic.round(work, bus, 4, *read, 1, 2);
    const uint64_t next = engine->cycle_count() + 50;
    REQUIRE(test::wait_until([&] { return task.done() || engine->cycle_count() >= next; }));
  }
  engine->stop();
  const auto counts = task.result();
  const auto faults = task.faults();
  INFO("new " << counts.new_calls << ", malloc " << counts.malloc_calls << " (first size "
              << counts.first_size << "), mutex locks " << counts.mutex_locks);
  INFO("traffic: " << traffic.sent << " messages submitted, " << traffic.replies << " replies, "
                   << traffic.acks << " acks, " << traffic.registers << " register reads");
  CHECK(counts.allocations() == 0);
  CHECK(counts.deallocations() == 0);
  CHECK(counts.mutex_locks == 0);
  if (!test::counts_mutexes()) WARN("TSan build: mutex locks are not counted; that check is void");
  INFO("page faults of the cycle thread: minor " << faults.minor << ", major " << faults.major);
  CHECK(faults.minor == 0);
  CHECK(faults.major == 0);
  // The readers slept and were woken all along, by the wake-up thread: the cycle thread rang it
  // at most once (when the first reader registered), never per cycle.
  INFO("readers got " << got[0] << ", " << got[1] << ", " << got[2] << ", " << got[3]
                      << " publications; wake-up calls " << publisher.wake_calls()
                      << ", rings by the cycle thread " << publisher.doorbell_calls());
  CHECK(publisher.doorbell_calls() <= 1);
  // (A floor, not a rate: how often a loaded machine lets the readers run is not the point.)
  for (const auto& g : got) CHECK(g.load() >= 10);
  CHECK(publisher.wake_calls() >= 10);
  // The traffic really went through the counted cycles.
  CHECK(traffic.replies > 100);
  CHECK(traffic.acks > 100);
  CHECK(traffic.registers > 100);
}
