// ds1928d with `bus: canio` on the cross-process virtual bus against the simulated CAN-I/O node:
// the module is configured at start over SDO, positions arrive in shared memory stamped with
// their reception time, `status` shows the CAN bus per node, and the EnDat commands of the
// socket (ident, read-param) work over Flatstream at MTU 5 and SDO.
#include "daemon.hpp"

#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <thread>

#include "../control/control_test_util.hpp"
#include "can/virtual_bus.hpp"
#include "cycle_work.hpp"
#include "rig.hpp"
#include "support/unix_socket.hpp"
#include "support/wait.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using json = nlohmann::json;

namespace {

struct SimulatedNodeThread {
  SimulatedNodeThread(const DaemonConfig& config, const std::string& bus_name,
                      const std::function<void(sim::CanioNodeConfig&)>& tweak = {}) {
    auto b = canio::VirtualCanBus::open_shared(bus_name,
                                               canio::virtual_bus_options(config.canio.bitrate));
    if (!b) throw std::runtime_error("virtual bus: " + b.error().message());
    bus = b.value();
    auto p = bus->open_port({});
    if (!p) throw std::runtime_error("virtual port: " + p.error().message());
    port = std::move(p.value());
    sim::CanioNodeConfig nc =
        sim::canio_node_from_config(config.canio, config.axes, config.simulated, 1);
    // Readable configuration registers: a node thread starved for input_timeout_ms on a loaded
    // machine is checked by read-back, not configured anew (which would restart the Flatstream
    // channel under an EnDat command this test is waiting for).
    nc.faults.config_write_only = false;
    if (tweak) tweak(nc);
    node = std::make_unique<sim::CanioNode>(nc, *port);
    if (node->open()) throw std::runtime_error("node filters");
    thread = std::thread([this] {
      while (!stop.load()) (void)node->service(test::Rig::monotonic() + 2'000'000);
    });
  }
  ~SimulatedNodeThread() { stop_serving(); }
  // After this the test may read the module's registers: the node thread no longer writes them.
  void stop_serving() {
    stop.store(true);
    if (thread.joinable()) thread.join();
  }
  std::shared_ptr<canio::VirtualCanBus> bus;
  std::unique_ptr<canio::VirtualCanPort> port;
  std::unique_ptr<sim::CanioNode> node;
  std::atomic<bool> stop{false};
  std::thread thread;
};

json request(const std::string& path, const json& j) {
  control::test::LineClient c(path, 10000);
  const json r = c.request(j);
  return r.is_object() ? r : json::object();
}

// A test's own virtual CAN bus, directory and shared-memory name (unique per process), removed
// when the test ends, and the daemon's configuration on them: one node, 2 ms.
struct TestPlace {
  explicit TestPlace(const std::string& name)
      : tag(std::to_string(::getpid())),
        bus("ds1928d-" + name + "-" + tag),
        dir(std::filesystem::temp_directory_path() / ("ds1928d-canio-" + name + "-" + tag)) {
    std::filesystem::create_directories(dir);
  }
  ~TestPlace() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
    (void)canio::VirtualCanBus::remove_shared(bus);
  }
  [[nodiscard]] DaemonConfig config(int nodes = 1) const {
    DaemonConfig c = test::canio_config(nodes, 2000);
    c.canio.virtual_bus = bus;
    // SYNC + 2 input objects take ~540 µs of a 500 kbit/s wire; the rest is the node thread's
    // and the daemon's reaction on a shared machine.
    c.canio.response_timeout_us = 1500;
    c.cycle.hold_cpu_dma_latency = false;
    c.cycle.lock_memory = false;
    c.shm.name = "/" + bus;
    c.socket.path = (dir / "control.sock").string();
    return c;
  }
  const std::string tag, bus;
  const std::filesystem::path dir;
};

// The daemon running on its own thread until the scope ends.
struct RunningDaemon {
  explicit RunningDaemon(const DaemonConfig& c)
      : daemon(c), thread([this] { rc = daemon.run(); }) {}
  ~RunningDaemon() {
    daemon.request_stop();
    thread.join();
  }
  Daemon daemon;
  int rc = -1;
  std::thread thread;
};

}  // namespace

TEST_CASE("ds1928d on bus canio: configured at start, positions, status, EnDat commands",
          "[canio][daemon][socket]") {
  const TestPlace place("daemon");
  const DaemonConfig c = place.config();
  SimulatedNodeThread node(c, place.bus);
  RunningDaemon running(c);
  REQUIRE(test::wait_until([&] { return test::unix_socket_accepts(c.socket.path); }));

  // Configured over SDO, then operational with fresh positions.
  json status;
  (void)test::wait_until([&] {
    status = request(c.socket.path, {{"cmd", "status"}});
    // The bus cycles at once; the axis is operational once configured and PosCycle moved.
    return status.value("ok", false) && status["bus"]["state"] == "operational" &&
           status["bus"]["nodes"][0]["state"] == "operational" &&
           status["bus"]["nodes"][0]["samples"].get<uint64_t>() > 50;
  });
  INFO(status.dump(2));
  REQUIRE(status["bus"]["kind"] == "canio");
  REQUIRE(status["bus"]["state"] == "operational");
  CHECK_FALSE(status["bus"].contains("cause"));  // only a state other than operational has one
  CHECK(status["bus"]["transport"] == "virtual");
  CHECK(status["bus"]["can_state"] == "error-active");
  CHECK(status["bus"]["nodes"][0]["configured"] == true);
  CHECK(status["bus"]["nodes"][0]["input_ids"] == json::array({0x281, 0x381}));
  CHECK(status["bus"]["nodes"][0]["output_id"] == 0x301);
  CHECK(status["bus"]["nodes"][0]["configurations"] == 1);
  // On the timed bus a cycle whose node thread was scheduled too late on a loaded machine is a
  // half sample (stale), as it would be on a real wire: wait for a valid one.
  json axes;
  (void)test::wait_until([&] {
    axes = request(c.socket.path, {{"cmd", "axes"}});
    return axes.is_object() && axes.contains("axes") && axes["axes"][0]["state"] == "valid";
  });
  INFO(axes.dump(2));
  CHECK(axes["axes"][0]["state"] == "valid");
  CHECK(axes["axes"][0]["time_source"] == "rx_timestamp");
  CHECK(axes["axes"][0]["pos_time_ns"].get<int64_t>() > 0);

  // POWERLINK's raw commands name the bus they need.
  CHECK(request(c.socket.path, {{"cmd", "pl-pres"}, {"node", 1}})["error"]["code"] ==
        "not_powerlink");

  const json ident = request(c.socket.path, {{"cmd", "endat-ident"}, {"axis", 0}});
  INFO(ident.dump(2));
  CHECK(ident.value("ok", false));
  const json param = request(
      c.socket.path, {{"cmd", "endat-read-param"}, {"axis", 0}, {"mrs", 0xA1}, {"param", 13}});
  INFO(param.dump(2));
  CHECK(param.value("ok", false));

  // Rescan over SDO (EnDatAck bit 1): written, read back until the module cleared it.
  const json rescan = request(c.socket.path, {{"cmd", "endat-rescan"}, {"axis", 0}});
  INFO(rescan.dump(2));
  CHECK(rescan.value("ok", false));
  CHECK(rescan.value("confirmed", false));
  const json ack = request(c.socket.path, {{"cmd", "endat-ack-register"}, {"axis", 0}});
  INFO(ack.dump(2));
  CHECK(ack.value("ok", false));
  CHECK(ack.value("confirmed", false));

  // The module really holds the configuration the daemon wrote (EnDat enabled, MTU 5).
  node.stop_serving();
  uint32_t v = 0;
  CHECK_FALSE(node.node->module(0).read_register(reg::kEnDatMode, 1, v));
  CHECK(v == endat_mode::kEnable);
  CHECK_FALSE(node.node->module(0).read_register(reg::kOutputMtu, 1, v));
  CHECK(v == 5);
}

TEST_CASE(
    "ds1928d on bus canio: a node with the wrong product is held down, the reason in status, "
    "topology and metrics",
    "[canio][daemon][topology]") {
  const TestPlace place("topo");
  DaemonConfig c = place.config();
  CanioNodeOptions expected;
  expected.node = 1;
  expected.identity.vendor_id = 0x0000001A;
  expected.identity.product_code = 0x00001928;
  c.canio.nodes.push_back(expected);
  c.metrics.listen.reset();
  SimulatedNodeThread node(c, place.bus,
                           [](sim::CanioNodeConfig& nc) { nc.identity.product_code = 0xBEEF; });
  RunningDaemon running(c);
  REQUIRE(test::wait_until([&] { return test::unix_socket_accepts(c.socket.path); }));

  json status;
  REQUIRE(test::wait_until([&] {
    status = request(c.socket.path, {{"cmd", "status"}});
    return status.value("ok", false) && status["bus"]["nodes"][0]["state"] == "identity_mismatch";
  }));
  INFO(status.dump(2));
  CHECK_THAT(status["bus"]["nodes"][0]["reason"].get<std::string>(),
             Catch::StartsWith("identity: product_code 0x0000BEEF, expected 0x00001928 "
                               "(0x1018/2); the node is not started"));
  CHECK(status["axes"][0]["state"] == "bus_down");
  CHECK(status["bus"]["canopen_nodes"][0]["identity"]["found"]["product_code"] == "0x0000BEEF");
  CHECK(node.node->nmt_state() == canio::NmtState::PreOperational);  // never started

  const json topo = request(c.socket.path, {{"cmd", "topology"}});
  INFO(topo.dump(2));
  REQUIRE(topo.value("ok", false));
  REQUIRE(topo["nodes"].size() == 1);
  CHECK(topo["nodes"][0]["state"] == "mismatch");
  CHECK(topo["nodes"][0]["held_down"] == true);
  CHECK(topo["nodes"][0]["expected"]["product_code"] == "0x00001928");
  CHECK(topo["nodes"][0]["found"]["product_code"] == "0x0000BEEF");
  CHECK(topo["nodes"][0]["difference"] ==
        "identity: product_code 0x0000BEEF, expected 0x00001928 (0x1018/2)");

  const std::string metrics = running.daemon.metrics_text(metrics::Format::Prometheus);
  CHECK_THAT(metrics, Catch::Contains("ds1928_canio_node_identity_mismatch{node=\"1\"} 1"));
  CHECK(running.daemon.cycle_work()
            .counters(0)
            .published[static_cast<std::size_t>(shm::AxisValidity::Valid)]
            .load() == 0);  // never a position from the wrong node
}

// The bus' state says what the axes say: with no node answering "no_nodes", with some
// "degraded", the nodes' SDO errors as the cause (plain `status` shows it), and the log names
// the same cause where the identification failed.
TEST_CASE("ds1928d on bus canio: no node answers -> no_nodes with the SDO cause",
          "[canio][daemon][socket]") {
  const TestPlace place("nonodes");
  const DaemonConfig c = place.config();
  // The bus exists, nobody serves node 1.
  auto vbus =
      canio::VirtualCanBus::open_shared(place.bus, canio::virtual_bus_options(c.canio.bitrate));
  REQUIRE(vbus);
  RunningDaemon running(c);
  REQUIRE(test::wait_until([&] { return test::unix_socket_accepts(c.socket.path); }));
  json status;
  (void)test::wait_until([&] {
    status = request(c.socket.path, {{"cmd", "status"}});
    return status.value("ok", false) && status["bus"]["state"] == "no_nodes";
  });
  INFO(status.dump(2));
  REQUIRE(status["bus"]["state"] == "no_nodes");
  REQUIRE(status["bus"].contains("cause"));
  const std::string cause = status["bus"]["cause"];
  CHECK(cause.find("no node answers") != std::string::npos);
  CHECK(cause.find("node 1:") != std::string::npos);
  CHECK(cause.find("no SDO response") != std::string::npos);
  CHECK(status["axes"][0]["state"] == "bus_down");
  // The failed identification's log line carries the same cause.
  CHECK(running.daemon.bus_service().axis_cause(0).find("no SDO response") != std::string::npos);
  // The metric says what status says (an alert on "operational" fires, and names the state).
  const std::string metrics = running.daemon.metrics_text(metrics::Format::Prometheus);
  CHECK_THAT(metrics, Catch::Contains("ds1928_bus_state{bus=\"canio\",state=\"no_nodes\"} 1"));
  CHECK_THAT(metrics, Catch::Contains("ds1928_bus_state{bus=\"canio\",state=\"operational\"} 0"));
}

TEST_CASE("ds1928d on bus canio: one of two nodes answers -> degraded, the silent one named",
          "[canio][daemon][socket]") {
  const TestPlace place("degraded");
  const DaemonConfig c = place.config(2);
  SimulatedNodeThread node(c, place.bus);  // node 1 only
  RunningDaemon running(c);
  REQUIRE(test::wait_until([&] { return test::unix_socket_accepts(c.socket.path); }));
  json status;
  (void)test::wait_until([&] {
    status = request(c.socket.path, {{"cmd", "status"}});
    return status.value("ok", false) && status["bus"]["state"] == "degraded";
  });
  INFO(status.dump(2));
  REQUIRE(status["bus"]["state"] == "degraded");
  const std::string cause = status["bus"].value("cause", "");
  CHECK(cause.find("1 of 2 node(s) answer") != std::string::npos);
  CHECK(cause.find("node 2:") != std::string::npos);
  CHECK(cause.find("node 1:") == std::string::npos);
  node.stop_serving();
}
