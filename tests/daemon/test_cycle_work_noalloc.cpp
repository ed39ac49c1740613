// The daemon's whole cycle (simulated bus exchange, decoding, Flatstream tunnels with EnDat
// traffic, acknowledgements, shared-memory publication) makes no heap allocation and takes no mutex
// on the cycle thread, over 100 000 steady cycles, while the normal thread keeps feeding it
// requests.
#include <unistd.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <thread>

#include "core/cycle_engine.hpp"
#include "cycle_proof.hpp"
#include "cycle_work.hpp"
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
  INFO("new " << counts.new_calls << ", malloc " << counts.malloc_calls << " (first size "
              << counts.first_size << "), mutex locks " << counts.mutex_locks);
  INFO("traffic: " << traffic.sent << " messages submitted, " << traffic.replies << " replies, "
                   << traffic.acks << " acks, " << traffic.registers << " register reads");
  CHECK(counts.allocations() == 0);
  CHECK(counts.deallocations() == 0);
  CHECK(counts.mutex_locks == 0);
  if (!test::counts_mutexes()) WARN("TSan build: mutex locks are not counted; that check is void");
  // The traffic really went through the counted cycles.
  CHECK(traffic.replies > 100);
  CHECK(traffic.acks > 100);
  CHECK(traffic.registers > 100);
}
