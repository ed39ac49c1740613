// The expected topology on the simulated bus: two axes, each behind a simulated X20DS1928 with the
// default simulated encoder (ID 1080790-02, serial S36845217); axis 1 expects another serial.
// With on_mismatch refuse exactly axis 1 stays bus_down with the reason in status, `topology`,
// metrics and the log, while axis 0 (its encoder as expected) is valid; with warn both publish and
// the difference is still reported. Pure comparison: encoder_differences.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <thread>

#include "../control/control_test_util.hpp"
#include "daemon.hpp"
#include "support/unix_socket.hpp"
#include "support/wait.hpp"
#include "topology.hpp"

using namespace ds1928;
using json = nlohmann::json;

namespace {

struct TopologyDaemon {
  explicit TopologyDaemon(bool refuse) {
    const std::string tag =
        std::string(refuse ? "refuse" : "warn") + "-" + std::to_string(::getpid());
    dir = std::filesystem::temp_directory_path() / ("ds1928d-topology-" + tag);
    std::filesystem::create_directories(dir);
    DaemonConfig c;
    c.cycle.period_us = 1000;
    c.cycle.hold_cpu_dma_latency = false;
    c.axes.resize(2);
    c.axes[0].name = "x";
    c.axes[1].name = "y";
    c.axes[1].slot = 2;
    c.axes[0].expected_encoder.id_number = "1080790-02";
    c.axes[0].expected_encoder.serial_number = "S36845217";
    c.axes[1].expected_encoder.id_number = "1080790-02";
    c.axes[1].expected_encoder.serial_number = "S99999999";  // the encoder was replaced
    c.topology.refuse = refuse;
    c.shm.name = "/ds1928d-topo-" + tag;
    c.socket.path = (dir / "control.sock").string();
    c.metrics.listen.reset();
    daemon = std::make_unique<Daemon>(c);
    thread = std::thread([this] { rc = daemon->run(); });
    REQUIRE(test::wait_until([&] { return test::unix_socket_accepts(c.socket.path); }));
    path = c.socket.path;
  }
  ~TopologyDaemon() {
    daemon->request_stop();
    thread.join();
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  json request(const json& j) {
    control::test::LineClient line(path, 5000);
    const json r = line.request(j);
    return r.is_object() ? r : json::object();
  }
  std::filesystem::path dir;
  std::string path;
  std::unique_ptr<Daemon> daemon;
  std::thread thread;
  int rc = -1;
};

}  // namespace

TEST_CASE("topology: a wrong encoder serial keeps exactly that axis down with the reason",
          "[daemon][topology]") {
  TopologyDaemon d(true);
  // Both identifications done: axis 0 confirmed and valid, axis 1 a mismatch.
  json axes;
  REQUIRE(test::wait_until([&] {
    axes = d.request({{"cmd", "axes"}});
    return axes.contains("axes") && axes["axes"][0].value("identity", "") == "confirmed" &&
           axes["axes"][1].value("identity", "") == "mismatch" &&
           axes["axes"][0].value("state", "") == "valid";
  }));
  // Held down for good: many cycles later it is still bus_down, axis 0 still valid.
  const uint64_t c0 = d.daemon->engine().cycle_count();
  REQUIRE(test::wait_until([&] { return d.daemon->engine().cycle_count() > c0 + 200; }));
  const json st = d.request({{"cmd", "status"}});
  REQUIRE(st.value("ok", false));
  CHECK(st["axes"][0]["state"] == "valid");
  CHECK(st["axes"][1]["state"] == "bus_down");
  CHECK(st["axes"][1]["identity"] == "mismatch");
  CHECK(st["axes"][1]["identity_reason"] ==
        "serial_number: expected 'S99999999', found 'S36845217'");
  CHECK_FALSE(st["axes"][0].contains("identity_reason"));
  // The module state like the r-LED: both modules run (the daemon, not the module, holds axis 1
  // down); no ErrorInfo bit, the e-LED is dark.
  CHECK(st["axes"][0]["module_state"] == "run");
  CHECK(st["axes"][1]["module_state"] == "run");
  CHECK(st["axes"][0]["module_error_class"] == "none");
  CHECK(st["axes"][0]["module"]["r_led"] == "on");
  CHECK(st["axes"][0]["module"]["e_led"] == "off");
  CHECK(st["axes"][0]["module"]["data_arrives"] == true);
  CHECK(d.daemon->cycle_work()
            .counters(1)
            .published[static_cast<std::size_t>(shm::AxisValidity::Valid)]
            .load() == 0);  // never a position under the wrong name

  const json t = d.request({{"cmd", "topology"}});
  REQUIRE(t.value("ok", false));
  CHECK(t["on_mismatch"] == "refuse");
  CHECK(t["axes"][0]["difference"].is_null());
  CHECK(t["axes"][0]["held_down"] == false);
  CHECK(t["axes"][1]["found"]["serial_number"] == "S36845217");
  CHECK(t["axes"][1]["expected"]["serial_number"] == "S99999999");
  CHECK(t["axes"][1]["held_down"] == true);
  CHECK(t["axes"][1]["difference"].get<std::string>().find("serial_number") != std::string::npos);
  CHECK(t["axes"][0]["module_state"] == "run");
  CHECK(t["axes"][1]["module_error_class"] == "none");

  const std::string metrics = d.daemon->metrics_text(metrics::Format::Prometheus);
  CHECK(metrics.find("ds1928_axis_identity_mismatch{axis=\"1\",name=\"y\"} 1") !=
        std::string::npos);
  CHECK(metrics.find("ds1928_axis_identity_mismatch{axis=\"0\",name=\"x\"} 0") !=
        std::string::npos);
  CHECK(metrics.find("ds1928_axis_module_state{axis=\"1\",name=\"y\",state=\"run\"} 1") !=
        std::string::npos);
  CHECK(metrics.find("ds1928_axis_module_state{axis=\"1\",name=\"y\",state=\"off\"} 0") !=
        std::string::npos);
}

TEST_CASE("topology: on_mismatch warn publishes and still reports the difference",
          "[daemon][topology]") {
  TopologyDaemon d(false);
  json axes;
  REQUIRE(test::wait_until([&] {
    axes = d.request({{"cmd", "axes"}});
    return axes.contains("axes") && axes["axes"][1].value("identity", "") == "mismatch" &&
           axes["axes"][1].value("state", "") == "valid";
  }));
  const json t = d.request({{"cmd", "topology"}});
  CHECK(t["on_mismatch"] == "warn");
  CHECK(t["axes"][1]["held_down"] == false);
  CHECK_FALSE(t["axes"][1]["difference"].is_null());
}

TEST_CASE("topology: encoder differences, field by field", "[daemon][topology]") {
  endat::Identification f;
  f.id.text[0] = '0';
  f.id.text[1] = '2';
  f.id.binary = 1080790;
  f.serial.prefix = 'S';
  f.serial.binary = 36845217;
  f.position_bits = 37;
  ExpectedEncoder e;
  CHECK(encoder_differences(e, f).empty());  // nothing expected
  e.id_number = "1080790-02";
  e.serial_number = "S36845217";
  e.position_bits = 37;
  CHECK(encoder_differences(e, f).empty());
  e.id_number = "1080790-01";
  e.position_bits = 25;
  const auto d = encoder_differences(e, f);
  REQUIRE(d.size() == 2);
  CHECK(d[0] == "id_number: expected '1080790-01', found '1080790-02'");
  CHECK(d[1] == "position_bits: expected 25, found 37");
}
