// The flight recorder on CAN-I/O: the driver raises the bus-off incident itself (on the cycle
// thread, through BusDriver::raise_incident) when its controller goes bus-off on the virtual CAN
// bus; the incident service writes one file holding the SocketCAN frames from before the event
// (SYNC, output and input objects) and the tail, which tshark reads without a malformed frame.
// The real clock (threaded rig): the frames' stamps and the incident's time are one timeline.
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <thread>

#include "capture/capturing_can_port.hpp"
#include "core/clock.hpp"
#include "incident_service.hpp"
#include "rig.hpp"

using namespace ds1928;
using namespace ds1928::test;

TEST_CASE("CAN-I/O: a bus-off is an incident with the frames before it in a file",
          "[canio][incident]") {
  char tmpl[] = "/tmp/ds1928-canio-incident.XXXXXX";
  const std::string dir = ::mkdtemp(tmpl);
  DaemonConfig config = canio_config(1);
  config.flight_recorder.dir = dir;
  config.flight_recorder.before_s = 5;
  config.flight_recorder.after_ms = 100;
  std::vector<capture::Tap*> taps;
  Rig rig(
      config, false, true, BusMode::Default,
      [&taps](std::unique_ptr<canio::CanPort> inner, bool sdo) -> std::unique_ptr<canio::CanPort> {
        auto p = std::make_unique<capture::CapturingCanPort>(std::move(inner),
                                                             sdo ? "can0 sdo" : "can0", 64);
        taps.push_back(&p->tap());
        return p;
      });
  IncidentService svc(config, taps, "canio");
  svc.open();
  rig.canio->set_incident_sink(&svc.sink());
  REQUIRE_FALSE(rig.canio->start());

  uint64_t c = 0;
  // Cycles back to back: each waits for its answers within the response window, nothing waits for
  // time to pass.
  auto cycle = [&] { (void)rig.cycle(c++); };
  for (int i = 0; i < 100; ++i) cycle();
  REQUIRE(rig.canio->state() == BusState::Operational);
  const int64_t before_off = rt::now_ns();
  REQUIRE(rig.driver_port->inject_bus_off());
  for (int i = 0; i < 50; ++i) cycle();
  // Once per bus-off: the cycles in bus-off raise nothing more.
  svc.poll(rt::now_ns() + 1'000'000'000);
  REQUIRE(svc.records().size() == 1);
  const IncidentRecord& r = svc.records().front();
  CHECK(r.kind == IncidentKind::BusOff);
  CHECK(r.count == 1);
  CHECK(r.time_ns >= before_off);
  REQUIRE_FALSE(r.file.empty());
  CHECK(r.file.find("-bus_off.pcapng") != std::string::npos);
  // 100 cycles before: the driver's own SYNC and output each (the node's inputs come on top,
  // as many as a loaded machine lets its thread answer).
  CHECK(r.frames >= 200);
  std::printf("canio incident test: %s, %llu frames, %llu bytes\n", r.file.c_str(),
              static_cast<unsigned long long>(r.frames), static_cast<unsigned long long>(r.bytes));

  if (std::system("command -v tshark >/dev/null 2>&1") == 0) {
    const std::string base = "tshark -r '" + r.file + "'";
    auto count = [](const std::string& cmd) {
      FILE* p = ::popen((cmd + " 2>/dev/null | wc -l").c_str(), "r");
      unsigned long n = 0;
      if (p != nullptr) {
        if (std::fscanf(p, "%lu", &n) != 1) n = 0;
        ::pclose(p);
      }
      return n;
    };
    const unsigned long total = count(base);
    const unsigned long bad = count(base + " -Y '_ws.malformed || _ws.expert.severity >= error'");
    const unsigned long can = count(base + " -Y can");
    const unsigned long sync_before =
        count(base + " -Y 'can.id == 0x80 && frame.time_epoch < " +
              std::to_string(static_cast<double>(r.realtime_ns) / 1e9) + "'");
    INFO("tshark: " << total << " frames, " << bad << " malformed, " << can << " CAN, "
                    << sync_before << " SYNC before the event");
    CHECK(total == r.frames);
    CHECK(bad == 0);
    CHECK(can == total);
    CHECK(sync_before >= 90);
  } else {
    WARN("tshark not installed: the file's decoding is not checked");
  }
  std::filesystem::remove_all(dir);
}
