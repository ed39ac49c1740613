// The daemon's whole cycle work over POWERLINK — PowerlinkBus on a real raw socket (SoC, PReq/PRes,
// SoA, ASnd with SDO transfers for register reads), axis decoding, the Flatstream tunnel with
// EnDat traffic, acknowledgements, shared-memory publication — makes no heap allocation and takes
// no mutex on the cycle thread once the bus is operational. Run by powerlink_veth_test.sh in the
// MN's network namespace with ds1928-sim answering on the other end of a veth pair:
//
//   powerlink_cycle_noalloc CONFIG [CYCLES] [capture] [foreign]
//
// With `capture` a capture runs on every capture point of the bus through the counted cycles
// (ds1928ctl capture: the cycle thread copies each frame into the tap's ring, this thread drains
// it) and the frames it took must be there. With `foreign` another MN's SoCs arrive throughout
// (the caller sends them): the counted cycles must have taken at least 10 of them, each counted,
// named and raised as an incident on the cycle thread. The flight recorder is on in both cases
// (every frame into its ring, incidents into the sink), as in the daemon.
//
// Exit 0: zero allocations and mutex locks with the traffic really flowing; 1: something counted
// or the traffic did not get through; 2: the bus did not come up (or a setup error).
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "capture/tap.hpp"
#include "config/config_loader.hpp"
#include "core/cycle_engine.hpp"
#include "cycle_proof.hpp"
#include "cycle_work.hpp"
#include "daemon.hpp"
#include "endat/command.hpp"
#include "incident_service.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "shm/publisher.hpp"
#include "support/alloc_counter.hpp"
#include "support/wait.hpp"

using namespace ds1928;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s CONFIG [CYCLES] [capture] [foreign]\n", argv[0]);
    return 2;
  }
  const uint64_t cycles = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 3000;
  bool with_capture = false;
  bool expect_foreign = false;
  for (int i = 3; i < argc; ++i) {
    const std::string word = argv[i];
    if (word == "capture") {
      with_capture = true;
    } else if (word == "foreign") {
      expect_foreign = true;
    } else {
      std::fprintf(stderr, "unknown word '%s' (capture, foreign)\n", argv[i]);
      return 2;
    }
  }
  const ConfigResult loaded = load_config(argv[1]);
  if (!loaded.ok()) {
    std::fprintf(stderr, "%s", loaded.error_report().c_str());
    return 2;
  }
  DaemonConfig config = loaded.config();
  config.shm.name = "/ds1928d-pl-noalloc-" + std::to_string(::getpid());
  config.cycle.hold_cpu_dma_latency = false;
  std::string why_not;
  std::unique_ptr<BusService> service = make_bus_service(config, why_not);
  if (!service) {
    std::fprintf(stderr, "bus: %s\n", why_not.c_str());
    return 2;
  }
  BusDriver* bus = &service->driver();
  // The flight recorder as the daemon runs it: the capture points record into their rings on the
  // cycle thread, which raises its incidents into the sink.
  IncidentService incidents(config, service->capture_taps(), "powerlink");
  bus->set_incident_sink(&incidents.sink());
  if (auto ec = bus->start()) {
    std::fprintf(stderr, "bus start: %s\n", ec.message().c_str());
    return 2;
  }
  shm::Publisher publisher;
  if (auto ec = publisher.open(config.shm, static_cast<uint32_t>(config.axes.size()),
                               config.cycle.period_us)) {
    std::fprintf(stderr, "shm: %s\n", ec.message().c_str());
    return 2;
  }
  CycleWork work(config, *bus, publisher);
  work.set_incident_sink(&incidents.sink());
  test::CountingTask task(work, cycles, 0, false);  // armed once the bus is operational
  auto engine = std::make_unique<CycleEngine>(config.cycle, task);
  if (auto started = engine->start(); !started) {
    std::fprintf(stderr, "cycle engine: %s\n", started.error.message().c_str());
    return 2;
  }

  if (!test::wait_until([&] { return bus->state() == BusState::Operational; })) {
    std::fprintf(stderr, "bus not operational within %lld s (state %s)\n",
                 static_cast<long long>(test::kWaitBound.count()),
                 std::string(to_string(bus->state())).c_str());
    engine->stop();
    bus->stop();
    return 2;
  }
  const auto taps = service->capture_taps();
  if (with_capture) {
    if (taps.empty()) {
      std::fprintf(stderr, "the bus has no capture point\n");
      return 2;
    }
    for (capture::Tap* tap : taps) (void)tap->begin();
  }
  uint64_t drained = 0;
  auto drain = [&] {
    for (capture::Tap* tap : taps)
      while (tap->pop([&](const capture::TapFrame&) { ++drained; })) {
      }
  };
  // Another MN's frames as the MN counts them (read on this thread, outside the counted work).
  const auto* powerlink_bus = dynamic_cast<const powerlink::PowerlinkBus*>(bus);
  auto foreign_frames = [&]() -> uint64_t {
    return powerlink_bus ? powerlink_bus->status().counters.foreign_mn_frames : 0;
  };
  task.arm();  // count from here on
  // Read after arming and again once the counted cycles are done: at most the few cycles between
  // done and this thread's look at it lie outside the window, which the margin of 10 covers.
  const uint64_t foreign_before = foreign_frames();
  uint64_t foreign_after = foreign_before;

  // The normal thread's traffic while the cycles are counted: EnDat read-param through the
  // Flatstream tunnel of every axis, error acknowledgements, register reads (SDO over ASnd).
  const auto read =
      endat::encode_request(endat::Request::read(0xA1, 13), endat::CommandSet::EnDat22);
  if (!read) return 2;
  test::CycleTraffic t;
  // One round every 5 cycles: traffic per counted cycle independent of the scheduler.
  while (!task.done()) {
    t.round(work, *bus, config.axes.size(), *read, 0, 0);
    if (with_capture) drain();
    const uint64_t next = engine->cycle_count() + 5;
    if (!test::wait_until([&] { return task.done() || engine->cycle_count() >= next; })) break;
  }
  foreign_after = foreign_frames();
  engine->stop();
  bus->stop();
  uint64_t dropped = 0;
  if (with_capture) {
    for (capture::Tap* tap : taps) {
      (void)tap->finish();
      dropped += tap->counters().dropped;
    }
    drain();
  }
  const test::HeapCounts counts = task.result();
  std::printf(
      "counted %llu cycles over POWERLINK: new %llu, malloc %llu (first size %zu), delete %llu, "
      "free %llu, mutex locks %llu\n",
      static_cast<unsigned long long>(cycles), static_cast<unsigned long long>(counts.new_calls),
      static_cast<unsigned long long>(counts.malloc_calls), counts.first_size,
      static_cast<unsigned long long>(counts.delete_calls),
      static_cast<unsigned long long>(counts.free_calls),
      static_cast<unsigned long long>(counts.mutex_locks));
  std::printf(
      "traffic: %llu EnDat messages sent, %llu replies, %llu acks, %llu register reads "
      "(%llu answered)\n",
      static_cast<unsigned long long>(t.sent), static_cast<unsigned long long>(t.replies),
      static_cast<unsigned long long>(t.acks), static_cast<unsigned long long>(t.registers),
      static_cast<unsigned long long>(t.register_results));
  uint64_t flight = 0;
  for (const capture::Tap* tap : taps)
    if (tap->flight_ring() != nullptr) flight += tap->flight_ring()->counters().frames;
  std::printf("flight recorder on: %llu frames recorded\n",
              static_cast<unsigned long long>(flight));
  const bool recorded = taps.empty() || flight >= cycles;
  if (!recorded) std::printf("FAIL: the flight recorder took fewer frames than cycles\n");
  if (with_capture)
    std::printf("capture on: %llu frames captured, %llu dropped\n",
                static_cast<unsigned long long>(drained), static_cast<unsigned long long>(dropped));
  const auto faults = task.faults();
  std::printf("page faults of the cycle thread: minor %ld, major %ld\n", faults.minor,
              faults.major);
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // Every sanitizer runtime intercepts mlockall and locks nothing (docs/testing.md): pages the
  // cycle thread touches late fault there. The page-fault proof is the normal build's.
  const bool no_faults = true;
  if (faults.minor != 0 || faults.major != 0)
    std::printf("sanitizer build: mlockall is intercepted, page faults are not judged\n");
#else
  const bool no_faults = faults.minor == 0 && faults.major == 0;
  if (!no_faults) std::printf("FAIL: the cycle thread took page faults in steady cycles\n");
#endif
  const uint64_t foreign = foreign_after - foreign_before;
  if (expect_foreign)
    std::printf("another MN's frames taken in the counted cycles: %llu\n",
                static_cast<unsigned long long>(foreign));
  const bool foreign_ok = !expect_foreign || foreign >= 10;
  if (!foreign_ok)
    std::printf("FAIL: fewer than 10 of another MN's frames in the counted cycles\n");
  const bool captured = !with_capture || drained >= cycles;
  if (!captured) std::printf("FAIL: the capture took fewer frames than cycles\n");
  const bool clean =
      counts.allocations() == 0 && counts.deallocations() == 0 && counts.mutex_locks == 0;
  const bool traffic = t.replies >= 10 && t.acks >= 10 && t.register_results >= 10;
  if (!clean) std::printf("FAIL: the cycle thread allocated or locked a mutex\n");
  if (!ds1928::test::counts_mutexes())
    std::printf("TSan build: mutex locks are not counted; the mutex check is void\n");
  if (!traffic) std::printf("FAIL: too little traffic went through the counted cycles\n");
  return clean && traffic && captured && recorded && no_faults && foreign_ok ? 0 : 1;
}
