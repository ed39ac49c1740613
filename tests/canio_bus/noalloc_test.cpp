// The daemon's whole cycle on `bus: canio` — SYNC, output objects, input objects, decoding,
// Flatstream tunnels with EnDat traffic, acknowledgements, shared memory — makes no heap
// allocation and takes no mutex on the cycle thread, while the normal thread feeds it EnDat
// commands and acyclic register reads. The register access over SDO runs on the cycle thread too
// (stepped by the cycle): the counted cycles configure the modules (write, read-back, Rescan),
// serve the reads and time out lost SDO requests. The simulated node answers from its own thread
// over the virtual bus.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <thread>

#include "core/cycle_engine.hpp"
#include "cycle_proof.hpp"
#include "cycle_work.hpp"
#include "endat/command.hpp"
#include "rig.hpp"
#include "shm/publisher.hpp"
#include "support/wait.hpp"

using namespace ds1928;

TEST_CASE("bus canio: the cycle allocates nothing and locks no mutex", "[canio][daemon][rt]") {
  DaemonConfig config = test::canio_config(2, 1000);
  config.canio.response_timeout_us = 500;
  config.cycle.hold_cpu_dma_latency = false;
  config.shm.name = "/ds1928d-canio-noalloc-" + std::to_string(::getpid());
  // Instant bus: 2 modules + SYNC need ~1.5 ms of wire at 500 kbit/s, more than this 1 ms cycle.
  test::Rig rig(config, false, false, test::BusMode::Instant);
  REQUIRE_FALSE(rig.canio->start());
  shm::Publisher publisher;
  REQUIRE_FALSE(publisher.open(config.shm, 2, 1'000'000));
  CycleWork work(config, *rig.canio, publisher);
  constexpr uint64_t kCounted = 3000;
  test::CountingTask task(work, kCounted, 0, false);  // armed once the modules are configured
  auto engine = std::make_unique<CycleEngine>(config.cycle, task);
  auto started = engine->start();
  REQUIRE(started);
  REQUIRE(test::wait_until([&] { return rig.canio->state() == BusState::Operational; }));
  auto sdo_totals = [&] {
    std::pair<uint64_t, uint64_t> t{0, 0};
    for (std::size_t i = 0; i < 2; ++i) {
      t.first += rig.canio->axis_counters(i).sdo_transfers.load();
      t.second += rig.canio->axis_counters(i).sdo_errors.load();
    }
    return t;
  };
  // Two requests to node 1 are lost: transfers in flight until sdo_timeout_ms, inside the count.
  rig.nodes[0]->drop_sdo_requests(2);
  const auto sdo_before = sdo_totals();
  task.arm();

  const auto read =
      endat::encode_request(endat::Request::read(0xA1, 13), endat::CommandSet::EnDat22);
  REQUIRE(read);
  test::CycleTraffic traffic;
  // One round every 5 cycles: the traffic per counted cycle does not depend on how the
  // scheduler shares the cores between this thread and the cycle thread.
  while (!task.done()) {
    traffic.round(work, *rig.canio, 2, *read, 1, 0);
    const uint64_t next = engine->cycle_count() + 5;
    REQUIRE(test::wait_until([&] { return task.done() || engine->cycle_count() >= next; }));
  }
  const auto sdo_after = sdo_totals();
  engine->stop();
  const auto counts = task.result();
  INFO("new " << counts.new_calls << ", malloc " << counts.malloc_calls << " (first size "
              << counts.first_size << "), mutex locks " << counts.mutex_locks);
  INFO("traffic: " << traffic.sent << " messages, " << traffic.replies << " replies, "
                   << traffic.acks << " acks, " << traffic.registers << " register reads, "
                   << traffic.register_results << " results");
  const uint64_t sdo_transfers = sdo_after.first - sdo_before.first;
  const uint64_t sdo_errors = sdo_after.second - sdo_before.second;
  std::printf(
      "canio noalloc: %llu cycles counted: %llu allocations, %llu mutex locks; %llu "
      "EnDat replies, %llu register results; %llu SDO transfers, %llu SDO errors\n",
      static_cast<unsigned long long>(kCounted),
      static_cast<unsigned long long>(counts.allocations()),
      static_cast<unsigned long long>(counts.mutex_locks),
      static_cast<unsigned long long>(traffic.replies),
      static_cast<unsigned long long>(traffic.register_results),
      static_cast<unsigned long long>(sdo_transfers), static_cast<unsigned long long>(sdo_errors));
  CHECK(counts.allocations() == 0);
  CHECK(counts.deallocations() == 0);
  CHECK(counts.mutex_locks == 0);
  CHECK(traffic.replies > 20);
  CHECK(traffic.register_results > 20);
  CHECK(sdo_transfers > 20);  // SDO in flight during the counted cycles
  CHECK(sdo_errors >= 2);     // the two lost requests timed out on the cycle thread
  CHECK(rig.canio->axis_counters(0).samples.load() > kCounted / 2);
}
