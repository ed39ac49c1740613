// The queues from the normal thread into the cycle thread are fixed rings: when the cycle does
// not drain them (here: no cycle runs at all) the producer is refused at the stated depth, which
// the socket commands report as "busy"; nothing grows.
#include <unistd.h>

#include <catch2/catch.hpp>

#include "cycle_work.hpp"
#include "shm/publisher.hpp"
#include "sim/simulated_bus.hpp"

using namespace ds1928;

TEST_CASE("the cycle thread's command and tunnel queues refuse past their depth",
          "[daemon][queue]") {
  DaemonConfig config;
  config.axes.resize(1);
  config.axes[0].name = "x";
  config.shm.name = "/ds1928d-queues-" + std::to_string(::getpid());
  sim::SimulatedBus bus(config.axes, config.simulated);
  shm::Publisher publisher;
  REQUIRE_FALSE(publisher.open(config.shm, 1, 1'000'000));
  CycleWork work(config, bus, publisher);

  // ack-errors: 64 commands; the 65th is "busy" at the socket.
  int posted = 0;
  while (posted < 1000 && work.post({AxisCommand::Kind::AckErrors, 0, 1})) ++posted;
  CHECK(posted == 64);

  // EnDat messages into an axis' Flatstream tunnel: 16 (EnDatService holds one per axis in
  // flight and queues 16 more itself, refusing the 17th with "busy").
  TunnelRequest request;
  request.size = 3;
  int submitted = 0;
  while (submitted < 1000 && work.submit_tunnel(0, request)) ++submitted;
  CHECK(submitted == 16);
  CHECK_FALSE(work.submit_tunnel(1, request));  // no such axis: refused, not out of bounds
  publisher.close();
}
