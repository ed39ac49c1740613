// The flight recorder's incidents (daemon/incident_service.*, incident_store.*): a manual mark and
// incidents raised on the cycle thread's sink become one pcapng file each, holding the frames of
// the window before the event and its tail, named in the journal field DS1928_INCIDENT_FILE; an
// identical incident during the tail joins the pending one; the incident directory stays within
// its bounds (count and bytes) under 1000 incidents, the oldest removed first; files of earlier
// runs are taken into account; the mapping of bus events to incidents.
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "capture/pcapng.hpp"
#include "capture/tap.hpp"
#include "core/clock.hpp"
#include "daemon.hpp"
#include "incident_service.hpp"
#include "incident_store.hpp"
#include "service/journal.hpp"

using namespace ds1928;
namespace fs = std::filesystem;

namespace {

struct TempDir {
  TempDir() {
    char tmpl[] = "/tmp/ds1928-incidents.XXXXXX";
    path = ::mkdtemp(tmpl);
  }
  ~TempDir() { fs::remove_all(path); }
  std::string path;
};

std::vector<uint8_t> read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

// The Enhanced Packet Blocks of a pcapng file we wrote: (interface, time ns since the epoch).
struct Epb {
  uint32_t interface;
  uint64_t time_ns;
  uint32_t length;
};
std::vector<Epb> epbs_of(const std::vector<uint8_t>& f) {
  std::vector<Epb> out;
  std::size_t off = 0;
  while (off + 12 <= f.size()) {
    uint32_t type = 0, len = 0;
    std::memcpy(&type, &f[off], 4);
    std::memcpy(&len, &f[off + 4], 4);
    if (len < 12 || off + len > f.size()) break;
    if (type == capture::kEnhancedPacketBlock) {
      uint32_t iface = 0, hi = 0, lo = 0, caplen = 0;
      std::memcpy(&iface, &f[off + 8], 4);
      std::memcpy(&hi, &f[off + 12], 4);
      std::memcpy(&lo, &f[off + 16], 4);
      std::memcpy(&caplen, &f[off + 20], 4);
      out.push_back({iface, (uint64_t{hi} << 32) | lo, caplen});
    }
    off += len;
  }
  return out;
}

std::vector<uint8_t> ethernet_frame(uint64_t n) {
  std::vector<uint8_t> f(60, 0);
  std::memset(f.data(), 0xFF, 6);  // broadcast
  f[12] = 0x88;
  f[13] = 0xAB;  // POWERLINK
  f[14] = 0x01;  // SoC
  std::memcpy(&f[20], &n, 8);
  return f;
}

// Captures what the default logger writes (the journal framing when structured logging is on).
struct LogCapture {
  LogCapture() {
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(text);
    sink->set_pattern("%v");
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("incident-test", sink));
    control::set_structured_logging(true);
  }
  ~LogCapture() {
    control::set_structured_logging(false);
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("", spdlog::sinks_init_list{}));
  }
  // The fields of the record whose text contains `needle`.
  std::map<std::string, std::string> fields_of(std::string_view needle) const {
    std::istringstream in(text.str());
    std::string line;
    while (std::getline(in, line)) {
      const control::SplitRecord r = control::split_record(line);
      if (r.text.find(needle) == std::string_view::npos) continue;
      std::map<std::string, std::string> m;
      for (std::size_t i = 0; i < r.field_count; ++i) {
        const auto eq = r.fields[i].find('=');
        m[std::string(r.fields[i].substr(0, eq))] = std::string(r.fields[i].substr(eq + 1));
      }
      return m;
    }
    return {};
  }
  std::ostringstream text;
};

DaemonConfig recorder_config(const std::string& dir) {
  DaemonConfig c;
  c.flight_recorder.dir = dir;
  c.flight_recorder.before_s = 2;
  c.flight_recorder.after_ms = 100;
  c.flight_recorder.ring_bytes = 256 * 1024;
  return c;
}

}  // namespace

TEST_CASE("incident: a manual mark writes the window before it and its tail, named in the journal",
          "[daemon][incident]") {
  TempDir dir;
  const DaemonConfig config = recorder_config(dir.path + "/incidents");
  capture::Tap tap("plk0", capture::kLinkTypeEthernet, 1514, 64);
  capture::Tap* taps[] = {&tap};
  IncidentService svc(config, taps, "powerlink");
  LogCapture log;
  svc.open();
  REQUIRE(tap.flight_ring() != nullptr);
  CHECK(fs::is_directory(dir.path + "/incidents"));

  // Frames 3 s, 1 s and 0.5 s before the event, then 50 ms and 300 ms after it.
  const int64_t t = rt::now_ns();
  const int64_t offsets_ms[] = {-3000, -1000, -500, 50, 300};
  for (uint64_t i = 0; i < 5; ++i)
    tap.record(capture::Direction::Inbound, t + offsets_ms[i] * 1000000, ethernet_frame(i));
  svc.raise(IncidentKind::Manual, -1, -1, "manual mark: test", t);
  svc.poll(t + 99 * 1000000);  // the tail is not over: nothing yet
  CHECK(svc.records().empty());
  svc.poll(t + 100 * 1000000);
  REQUIRE(svc.records().size() == 1);
  const IncidentRecord& r = svc.records().front();
  REQUIRE_FALSE(r.file.empty());
  CHECK(r.kind == IncidentKind::Manual);
  // Inside [t - 2 s, t + 100 ms]: the frames at -1 s, -0.5 s and +50 ms.
  CHECK(r.frames == 3);
  const auto file = read_file(r.file);
  CHECK(file.size() == r.bytes);
  const auto epbs = epbs_of(file);
  REQUIRE(epbs.size() == 3);
  const auto event_real = static_cast<uint64_t>(r.realtime_ns);
  CHECK(epbs[0].time_ns < event_real);  // frames from before the event
  CHECK(epbs[1].time_ns < event_real);
  CHECK(epbs[2].time_ns > event_real);  // and the tail
  CHECK(epbs[0].length == 60);
  CHECK(fs::path(r.file).filename().string().find("-manual") != std::string::npos);

  const auto fields = log.fields_of("incident 1:");
  CHECK(fields.at("MESSAGE_ID") == control::message_id(control::LogEvent::Incident));
  CHECK(fields.at("DS1928_INCIDENT_FILE") == r.file);
  CHECK(fields.at("DS1928_INCIDENT") == "manual");
  CHECK(fields.at("DS1928_BUS") == "powerlink");

  const auto list = svc.list_json();
  REQUIRE(list.at("incidents").size() == 1);
  CHECK(list["incidents"][0]["file"] == r.file);
  CHECK(list["incidents"][0]["frames"] == 3);
  CHECK(list["incidents"][0]["kind"] == "manual");
}

TEST_CASE("incident: the cycle thread's sink, joins during the tail, kinds in the file name",
          "[daemon][incident]") {
  TempDir dir;
  const DaemonConfig config = recorder_config(dir.path);
  capture::Tap tap("can0", capture::kLinkTypeCanSocketCan, 16, 64);
  capture::Tap* taps[] = {&tap};
  IncidentService svc(config, taps, "canio");
  LogCapture log;
  svc.open();
  const int64_t t = rt::now_ns();
  tap.record(capture::Direction::Outbound, t - 1000000, std::vector<uint8_t>(16, 1));
  REQUIRE(svc.sink().raise(IncidentKind::BusOff, -1, -1, t));
  REQUIRE(svc.sink().raise(IncidentKind::BusOff, -1, -1, t + 1000));      // joins
  REQUIRE(svc.sink().raise(IncidentKind::AxisBusDown, -1, 0, t + 2000));  // its own
  REQUIRE(svc.sink().raise(IncidentKind::NodeBootUp, 5, -1, t + 3000));   // its own
  svc.poll(t + 200 * 1000000);
  REQUIRE(svc.records().size() == 3);
  CHECK(svc.records()[0].kind == IncidentKind::BusOff);
  CHECK(svc.records()[0].count == 2);
  CHECK(svc.records()[0].frames == 1);
  CHECK(svc.records()[1].file.find("-axis_bus_down-a0.pcapng") != std::string::npos);
  CHECK(svc.records()[2].file.find("-boot_up-n5.pcapng") != std::string::npos);
  CHECK(log.fields_of("incident 3:").at("DS1928_NODE") == "5");
  const auto st = svc.status_json();
  CHECK(st["raised"]["bus_off"] == 2);
  CHECK(st["joined"] == 1);
  CHECK(st["written"] == 3);
  // The sink's bound: a full queue drops and counts, never blocks.
  for (std::size_t i = 0; i < IncidentSink::kCapacity; ++i)
    (void)svc.sink().raise(IncidentKind::OverrunBurst);
  CHECK_FALSE(svc.sink().raise(IncidentKind::OverrunBurst));
  CHECK(svc.sink().dropped() == 1);
}

TEST_CASE("incident store: 1000 incidents keep the directory within its bounds, oldest first",
          "[daemon][incident]") {
  TempDir dir;
  // Bounded by count: 20 files.
  {
    IncidentStore store(dir.path + "/count", 20, 1 << 30);
    REQUIRE_FALSE(store.open());
    for (uint64_t i = 1; i <= 1000; ++i) {
      const std::vector<uint8_t> bytes(100 + i % 50, 0xAB);
      REQUIRE_FALSE(store.write(
          incident_file_name(1'800'000'000'000'000'000 + i * 1000, i, "manual", -1, -1), bytes));
      std::size_t on_disk = 0;
      for (const auto& e : fs::directory_iterator(dir.path + "/count")) (void)e, ++on_disk;
      REQUIRE(on_disk == std::min<uint64_t>(i, 20));
    }
    CHECK(store.files() == 20);
    CHECK(store.removed() == 980);
    // The newest 20 are there: 981..1000.
    CHECK(store.list().front().name.find("-000981-") != std::string::npos);
    CHECK(store.list().back().name.find("-001000-") != std::string::npos);
  }
  // Bounded by bytes: 1 MiB total, files of 100 KiB + i.
  {
    constexpr uint64_t kMax = 1 << 20;
    IncidentStore store(dir.path + "/bytes", 100000, kMax);
    REQUIRE_FALSE(store.open());
    uint64_t largest_total = 0;
    for (uint64_t i = 1; i <= 1000; ++i) {
      const std::vector<uint8_t> bytes(100 * 1024 + i, 0xCD);
      REQUIRE_FALSE(store.write(
          incident_file_name(1'800'000'000'000'000'000 + i * 1000, i, "node_lost", 1, -1), bytes));
      uint64_t on_disk = 0;
      for (const auto& e : fs::directory_iterator(dir.path + "/bytes")) on_disk += e.file_size();
      REQUIRE(on_disk <= kMax);
      REQUIRE(on_disk == store.total_bytes());
      largest_total = std::max(largest_total, on_disk);
    }
    CHECK(store.files() == 10);  // 10 × ~100 KiB fit in 1 MiB, 11 do not
    CHECK(largest_total > kMax - 110 * 1024);
    // A single file larger than the whole bound is refused, nothing removed for it.
    CHECK(store.write(incident_file_name(1'900'000'000'000'000'000, 1001, "manual", -1, -1),
                      std::vector<uint8_t>(kMax + 1, 0)) ==
          std::make_error_code(std::errc::file_too_large));
    CHECK(store.files() == 10);
  }
  // A restart takes stock of the files there (earlier runs) and prunes them to its bounds; files
  // that are not incident files are left alone.
  {
    std::ofstream(dir.path + "/count/notes.txt") << "mine";
    IncidentStore store(dir.path + "/count", 5, 1 << 30);
    REQUIRE_FALSE(store.open());
    CHECK(store.files() == 5);
    CHECK(store.list().back().name.find("-001000-") != std::string::npos);
    CHECK(fs::exists(dir.path + "/count/notes.txt"));
  }
}

TEST_CASE("incident: a directory that cannot be made leaves the recorder running without files",
          "[daemon][incident]") {
  TempDir dir;
  std::ofstream(dir.path + "/file") << "x";
  const DaemonConfig config = recorder_config(dir.path + "/file/incidents");  // under a file
  capture::Tap tap("plk0", capture::kLinkTypeEthernet, 1514, 64);
  capture::Tap* taps[] = {&tap};
  IncidentService svc(config, taps, "powerlink");
  LogCapture log;
  svc.open();
  svc.raise(IncidentKind::Manual, -1, -1, "x");
  svc.poll(0, true);
  REQUIRE(svc.records().size() == 1);
  CHECK(svc.records()[0].file.empty());
  CHECK(svc.records()[0].error == "no incident directory");
  CHECK(log.text.str().find("no incident file will be written") != std::string::npos);
}

TEST_CASE("incident: which bus events are incidents", "[daemon][incident]") {
  const BusEvent threshold(true, "t", control::LogEvent::NodeReset, 1, -1,
                           "loss of PRes threshold reached");
  const BusEvent lost(true, "t", control::LogEvent::NodeReset, 1, -1, "node not operational");
  const BusEvent other(true, "t", control::LogEvent::NodeReset, 1, -1, "boot step timed out");
  const BusEvent silent(true, "t", control::LogEvent::NodeSilent, 3, 0);
  const BusEvent operational(false, "t", control::LogEvent::NodeOperational, 1);
  CHECK(incident_of(threshold) == IncidentKind::PresThreshold);
  CHECK(incident_of(lost) == IncidentKind::NodeLost);
  CHECK(incident_of(other) == IncidentKind::NodeReset);
  CHECK(incident_of(silent) == IncidentKind::NodeLost);
  CHECK_FALSE(incident_of(operational).has_value());
  // CAN-I/O node lifecycle (canio_service.cpp): boot-up and a missed heartbeat have kinds of their
  // own; NMT Start repeated to a silent node is no new incident.
  const BusEvent boot_up(true, "t", control::LogEvent::NodeReset, 2, -1, "boot-up");
  const BusEvent heartbeat(true, "t", control::LogEvent::NodeSilent, 2, -1, "heartbeat-missed");
  const BusEvent start_retry(true, "t", control::LogEvent::NodeSilent, 2, -1, "start-retry");
  CHECK(incident_of(boot_up) == IncidentKind::NodeBootUp);
  CHECK(incident_of(heartbeat) == IncidentKind::HeartbeatMissed);
  CHECK_FALSE(incident_of(start_retry).has_value());
}
