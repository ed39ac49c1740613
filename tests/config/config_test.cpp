// Configuration loader: every bad fixture in tests/config/bad/ must be refused with the exact
// file, line, column, key path and message; the shipped example configs must load; defaults
// must be the datasheet's.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "config/config_loader.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace {

using namespace ds1928;

const std::string kSource = DS1928_SOURCE_DIR;
const std::string kBad = kSource + "/tests/config/bad/";

struct Expected {
  const char* file;
  int line;
  int column;
  const char* key;
  const char* message;  // must appear in the error's message
};

// One row per fixture; the directory walk below makes sure no fixture goes unchecked.
const Expected kBadFiles[] = {
    {"unknown_key.yaml", 3, 3, "cycle.perod_us",
     "unknown key 'perod_us' (did you mean 'period_us'?)"},
    {"wrong_type.yaml", 3, 16, "cycle.rt_priority",
     "expected an integer (decimal or 0x hex) in 1..99 (SCHED_FIFO), got 'high'"},
    {"output_mtu_fm0.yaml", 6, 19, "axes[0].module.output_mtu",
     "16 is out of range 2..15 for function model 0"},
    {"input_mtu_fm254.yaml", 8, 18, "axes[0].module.input_mtu",
     "6 is out of range 3..5 for function model 254"},
    {"forward.yaml", 3, 16, "axes[0].module.forward", "0 is out of range 1..7"},
    {"prescaler.yaml", 4, 25, "axes[1].module.prescaler", "1 is out of range 2..65535"},
    {"rt_priority.yaml", 2, 16, "cycle.rt_priority", "100 is out of range 1..99"},
    {"period.yaml", 3, 14, "cycle.period_us", "50 is out of range 100..100000 µs"},
    {"vss_window.yaml", 4, 19, "axes[0].module.vss_min_mv",
     "vss_min_mv (1300) must not exceed vss_max_mv (1200)"},
    {"duplicate_name.yaml", 4, 11, "axes[1].name",
     "axis name 'x' is already used by axes[0] (line 2)"},
    {"duplicate_slot.yaml", 5, 5, "axes[1]", "node 1 slot 3 is already used by axes[0] (line 2)"},
    {"missing_bus_section.yaml", 3, 6, "bus",
     "bus is 'powerlink' but the file has no powerlink section"},
    {"unknown_node.yaml", 10, 11, "axes[1].node",
     "node 3 is not listed in powerlink.nodes (listed: 1)"},
    {"spin.yaml", 3, 12, "cycle.spin_us", "spin_us (200) must be less than cycle.period_us (200)"},
    {"sim_count.yaml", 3, 5, "simulated.axes", "2 entries but only 1 axes are configured"},
    {"bad_bus.yaml", 1, 6, "bus",
     "'powerlnk' is not allowed; expected one of: simulated, powerlink, canio (did you mean "
     "'powerlink'?)"},
    {"bad_mode.yaml", 3, 9, "shm.mode",
     "expected an octal file mode such as \"0640\", got the string \"0999\""},
    {"quoted_number.yaml", 2, 14, "cycle.period_us",
     "got the string \"1000\" (write the number without quotes)"},
    {"leading_zero.yaml", 3, 18, "axes[0].module.prescaler", "'04' has a leading zero"},
    {"syntax.yaml", 4, 1, "", "YAML syntax error: end of sequence flow not found"},
    {"duplicate_key.yaml", 3, 3, "cycle.period_us", "duplicate key (first given at line 2)"},
    {"slframe.yaml", 3, 23, "axes[0].module.slframe_gen_id",
     "10 is not allowed; expected 9 (fastest response) or 14"},
    {"function_model_bus.yaml", 7, 21, "axes[0].function_model",
     "254 is not allowed on bus powerlink"},
    {"pres_timeout.yaml", 8, 24, "powerlink.nodes[0].pres_timeout_us",
     "pres_timeout_us (250) must be less than cycle.period_us (200)"},
    {"shm_name.yaml", 2, 9, "shm.name", "is not a shared-memory name"},
    {"nmt.yaml", 7, 27, "powerlink.nmt.status_request_every", "0 is out of range 1..10000 cycles"},
    {"not_a_map.yaml", 1, 8, "cycle", "expected a map of settings, got '1000'"},
    {"offset_overlap.yaml", 13, 18, "axes[1].pres_offset",
     "PRes block of node 1 slot 2 (bytes 10..32) overlaps slot 1 (bytes 0..22) of axes[0] "
     "(line 7)"},
    {"offset_bus.yaml", 4, 18, "axes[0].preq_offset",
     "is only meaningful on bus powerlink (the bus here is simulated)"},
    {"huge_value.yaml", 3, 14, "cycle.period_us", "xxxxxxxx... (5000 characters)'"},
    {"interface_too_long.yaml", 4, 14, "powerlink.interface",
     "is 17 characters long; at most 15 are allowed"},
    {"encoder_not_regular.yaml", 4, 21, "simulated.axes[0].encoder_file",
     "not a regular file: /dev/zero is a character device"},
    {"deep_nesting.yaml", 3, 1, "", "YAML nested deeper than"},
    {"billion_laughs.yaml", 4, 3, "log_level", "a list is not allowed"},
    {"canio_node.yaml", 6, 11, "axes[0].node", "200 is out of range 1..127"},
    {"canio_mtu.yaml", 7, 18, "axes[0].module.input_mtu",
     "2 is out of range 3..5 for function model 254 (datasheet §11.3: Tx/RxByte1..5"},
    {"canio_id_collision.yaml", 10, 18, "canio.axes[1]",
     "CAN identifier 0x181 of axes[1] (b) input object 2 is already used by axes[0] (a) input "
     "object 1"},
    {"canio_bus_load.yaml", 3, 14, "cycle.period_us",
     "2000 µs loads the CAN-I/O bus to 138 %, above canio.max_bus_load 70 %: 10 frames a cycle "
     "(3 module(s) × 3 + SYNC) take 2540 µs with worst-case stuffing at 500000 bit/s, the SDO "
     "worker's share 216 µs; use period_us ≥ 4291"},
    {"canio_analog_slot.yaml", 5, 26, "canio.axes[0].first_analog_slot",
     "analog slots 3 and 4 need TPDO4 and TPDO5"},
    {"canio_transport.yaml", 5, 16, "canio.acyclic.transport",
     "'sdo' is not allowed; expected one of: canopen_sdo, none"},
};

void check_bad(const Expected& e) {
  const std::string path = kBad + e.file;
  const ConfigResult r = load_config(path);
  INFO(r.error_report());
  REQUIRE_FALSE(r.ok());
  REQUIRE(r.errors().size() == 1);
  const ConfigError& err = r.errors().front();
  CHECK(err.file == path);
  CHECK(err.line == e.line);
  CHECK(err.column == e.column);
  CHECK(err.key == e.key);
  CHECK_THAT(err.message, Catch::Contains(e.message));
  CHECK_THAT(err.to_string(), Catch::StartsWith(path + ":" + std::to_string(e.line) + ":" +
                                                std::to_string(e.column) + ": "));
}

const Expected& row(std::string_view file) {
  for (const auto& e : kBadFiles) {
    if (file == e.file) return e;
  }
  FAIL("no expectation for " << file);
  return kBadFiles[0];
}

ConfigResult from(std::string_view text) {
  return load_config_from_string(text, "test.yaml");
}

std::string one_error(std::string_view text) {
  const ConfigResult r = from(text);
  INFO(r.error_report());
  REQUIRE(r.errors().size() == 1);
  return r.errors().front().to_string();
}

}  // namespace

#define BAD_FIXTURE(name)                          \
  TEST_CASE("bad config " name, "[config][bad]") { \
    check_bad(row(name));                          \
  }

BAD_FIXTURE("unknown_key.yaml")
BAD_FIXTURE("wrong_type.yaml")
BAD_FIXTURE("output_mtu_fm0.yaml")
BAD_FIXTURE("input_mtu_fm254.yaml")
BAD_FIXTURE("forward.yaml")
BAD_FIXTURE("prescaler.yaml")
BAD_FIXTURE("rt_priority.yaml")
BAD_FIXTURE("period.yaml")
BAD_FIXTURE("vss_window.yaml")
BAD_FIXTURE("duplicate_name.yaml")
BAD_FIXTURE("duplicate_slot.yaml")
BAD_FIXTURE("missing_bus_section.yaml")
BAD_FIXTURE("unknown_node.yaml")
BAD_FIXTURE("spin.yaml")
BAD_FIXTURE("sim_count.yaml")
BAD_FIXTURE("bad_bus.yaml")
BAD_FIXTURE("bad_mode.yaml")
BAD_FIXTURE("quoted_number.yaml")
BAD_FIXTURE("leading_zero.yaml")
BAD_FIXTURE("syntax.yaml")
BAD_FIXTURE("duplicate_key.yaml")
BAD_FIXTURE("slframe.yaml")
BAD_FIXTURE("function_model_bus.yaml")
BAD_FIXTURE("pres_timeout.yaml")
BAD_FIXTURE("shm_name.yaml")
BAD_FIXTURE("nmt.yaml")
BAD_FIXTURE("not_a_map.yaml")
BAD_FIXTURE("offset_overlap.yaml")
BAD_FIXTURE("offset_bus.yaml")
BAD_FIXTURE("huge_value.yaml")
BAD_FIXTURE("interface_too_long.yaml")
BAD_FIXTURE("encoder_not_regular.yaml")
BAD_FIXTURE("deep_nesting.yaml")
BAD_FIXTURE("billion_laughs.yaml")

TEST_CASE("every bad fixture has an expectation and fails", "[config][bad]") {
  std::set<std::string> listed;
  for (const auto& e : kBadFiles) listed.insert(e.file);
  size_t seen = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kBad)) {
    const std::string name = entry.path().filename().string();
    if (entry.path().extension() != ".yaml" || name == "multi_error.yaml") continue;
    ++seen;
    CHECK(listed.count(name) == 1);
    CHECK_FALSE(load_config(entry.path().string()).ok());
  }
  CHECK(seen == listed.size());
  CHECK(seen >= 12);
}

TEST_CASE("all errors of a file are reported, in document order", "[config]") {
  const std::string path = kBad + "multi_error.yaml";
  const ConfigResult r = load_config(path);
  REQUIRE_FALSE(r.ok());
  INFO(r.error_report());
  const std::vector<std::tuple<int, int, std::string, std::string>> expected = {
      {3, 14, "cycle.period_us", "99 is out of range 100..100000"},
      {4, 3, "cycle.rt_prio", "did you mean 'rt_priority'?"},
      {9, 19, "axes[0].module.output_mtu", "16 is out of range 2..15 for function model 0"},
      {10, 16, "axes[0].module.forward", "9 is out of range 1..7"},
      {11, 11, "axes[1].name", "axis name 'a' is already used by axes[0]"},
      {13, 9, "shm.mode", "expected an octal file mode"},
  };
  REQUIRE(r.errors().size() == expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    const auto& [line, column, key, message] = expected[i];
    const ConfigError& e = r.errors()[i];
    CHECK(e.line == line);
    CHECK(e.column == column);
    CHECK(e.key == key);
    CHECK_THAT(e.message, Catch::Contains(message));
  }
  // The report is the same list, one line each.
  const std::string report = r.error_report();
  CHECK(std::count(report.begin(), report.end(), '\n') == static_cast<long>(expected.size()));
  CHECK_THAT(report, Catch::StartsWith(path + ":3:14: cycle.period_us: 99 is out of range"));
}

TEST_CASE("the example configurations load", "[config][examples]") {
  SECTION("simulated.yaml is the documented default") {
    const ConfigResult r = load_config(kSource + "/config/simulated.yaml");
    INFO(r.error_report());
    REQUIRE(r.ok());
    const DaemonConfig& c = r.config();
    CHECK(c.bus == BusKind::Simulated);
    REQUIRE(c.axes.size() == 1);
    CHECK(c.axes[0].name == "axis0");
    CHECK(c.shm.name == "/ds1928d");
    CHECK(c.socket.path == "/run/ds1928d/control.sock");
    // Written out in full, it must say exactly what an empty file means.
    const ConfigResult empty = from("");
    REQUIRE(empty.ok());
    DaemonConfig a = c;
    DaemonConfig b = empty.config();
    a.source_file = b.source_file = "";
    CHECK(dump_config(a) == dump_config(b));
  }
  SECTION("powerlink.yaml") {
    const ConfigResult r = load_config(kSource + "/config/powerlink.yaml");
    INFO(r.error_report());
    REQUIRE(r.ok());
    const DaemonConfig& c = r.config();
    CHECK(c.bus == BusKind::Powerlink);
    CHECK(c.powerlink.interface == "eth1");
    REQUIRE(c.powerlink.nodes.size() == 2);
    CHECK(c.powerlink.nodes[0].vendor_id == 0x1Au);
    CHECK_FALSE(c.powerlink.nodes[0].preq_size.has_value());
    CHECK_FALSE(c.powerlink.nodes[1].mandatory);
    REQUIRE(c.axes.size() == 3);
    CHECK(c.axes[0].module.output_mtu == 15);
    CHECK(c.axes[1].module.prescaler == 4);
    CHECK(c.axes[1].module.endat_mode() == 0x03);
    CHECK(c.axes[2].node == 2);
    CHECK(c.shm.group == "ds1928");
    CHECK(c.simulated.axes.size() == 3);
  }
  SECTION("canio.yaml") {
    const ConfigResult r = load_config(kSource + "/config/canio.yaml");
    INFO(r.error_report());
    REQUIRE(r.ok());
    const DaemonConfig& c = r.config();
    CHECK(c.bus == BusKind::Canio);
    CHECK(c.canio.little_endian);
    CHECK(c.canio.bitrate == 500000u);
    REQUIRE(c.axes.size() == 1);
    CHECK(c.axes[0].function_model == FunctionModel::BusController);
    CHECK(c.axes[0].module.output_mtu == 5);
  }
}

TEST_CASE("defaults are the datasheet's", "[config][defaults]") {
  const ConfigResult r = from("");
  REQUIRE(r.ok());
  const DaemonConfig& c = r.config();
  REQUIRE(c.axes.size() == 1);  // a config without axes gets one simulated axis
  const AxisConfig& a = c.axes[0];
  CHECK(a.name == "axis0");
  CHECK(a.node == 1);
  CHECK(a.slot == 1);
  CHECK(a.function_model == FunctionModel::Standard);
  const ModuleSettings& m = a.module;
  CHECK(m.prescaler == 2);        // X20DS1928.md §3: 2 = bus-controller default
  CHECK(m.slframe_gen_id == 14);  // X2X-cycle aligned
  CHECK(m.error_enable == 0xFF);  // every detection on
  CHECK(m.vss_min_mv == 800);
  CHECK(m.vss_max_mv == 1200);
  CHECK(m.quit_time_us == 100000u);
  // EnDatMode: the datasheet's 0 except bit 0, which the daemon sets so the encoder is read.
  CHECK(m.endat_mode() == endat_mode::kEnable);
  CHECK(m.forward >= 1);
  CHECK(c.bus == BusKind::Simulated);
  CHECK(c.cycle.spin_us == 0u);
  CHECK(c.cycle.hold_cpu_dma_latency);
  CHECK(c.shm.mode == 0640u);
  CHECK(c.socket.mode == 0660u);
  REQUIRE(c.simulated.axes.size() == 1);
  CHECK(c.simulated.axes[0].module_cycle_us == 100u);
  CHECK(c.log_level == "info");
  // Comments only is the same as empty.
  REQUIRE(from("# nothing here\n\n").ok());
}

TEST_CASE("simulated faults: the encoder's words, Vss, supply and their delay, range-checked",
          "[config][simulated]") {
  const ConfigResult r = from(R"(
simulated:
  axes:
    - {endat_error: 0x41, endat_warning: 0x03, vss_mv: 300, supply_mv: 4500, faults_after_ms: 500}
)");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const SimAxisConfig& a = r.config().simulated.axes[0];
  CHECK(a.endat_error == 0x41);
  CHECK(a.endat_warning == 0x03);
  CHECK(a.vss_mv == 300u);
  CHECK(a.supply_mv == 4500u);
  CHECK(a.faults_after_ms == 500u);
  const ConfigResult bad = from("simulated:\n  axes:\n    - {endat_warning: 0x20}\n");
  REQUIRE_FALSE(bad.ok());
  CHECK_THAT(bad.error_report(), Catch::Contains("simulated.axes[0].endat_warning"));
}

TEST_CASE("numbers accept decimal and 0x hex, modes are octal", "[config][numbers]") {
  const ConfigResult r = from(R"(
cycle: {period_us: 0x3E8, cpu: -1}
axes:
  - module: {error_enable: 0xfd, quit_time_us: 0X10, prescaler: 0x0004}
simulated:
  axes:
    - {inject_error_info: 0x14, velocity_periods_per_s: -2.5e2}
powerlink:
  nettime_offset_us: -0x10
  nodes:
    - {node_id: 1, vendor_id: 0xFFFFFFFF}
shm: {mode: 0600}
socket: {mode: "0o640"}
)");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const DaemonConfig& c = r.config();
  CHECK(c.cycle.period_us == 1000u);
  CHECK(c.axes[0].module.error_enable == 0xFD);
  CHECK(c.axes[0].module.quit_time_us == 16u);
  CHECK(c.axes[0].module.prescaler == 4);
  CHECK(c.simulated.axes[0].inject_error_info == 0x14);
  CHECK(c.simulated.axes[0].velocity_periods_per_s == -250.0);
  CHECK(c.simulated.axes[0].endat_warning == 0);
  CHECK(c.simulated.axes[0].supply_mv == 5000u);
  CHECK(c.powerlink.nettime_offset_us == -16);
  CHECK(c.powerlink.nodes[0].vendor_id == 0xFFFFFFFFu);
  CHECK(c.shm.mode == 0600u);
  CHECK(c.socket.mode == 0640u);

  CHECK_THAT(
      one_error("cycle: {period_us: 0x}"),
      Catch::Contains("expected an integer (decimal or 0x hex) in 100..100000 µs, got '0x'"));
  CHECK_THAT(one_error("cycle: {period_us: 1000.5}"), Catch::Contains("expected an integer"));
  CHECK_THAT(one_error("powerlink: {nodes: [{node_id: 1, vendor_id: 0x100000000}]}"),
             Catch::Contains("0x100000000 is out of range 0..4294967295"));
  CHECK_THAT(one_error("cycle: {period_us: 99999999999999999999999}"),
             Catch::Contains("is out of range 100..100000"));
  CHECK_THAT(one_error("shm: {mode: 01777}"), Catch::Contains("out of range 0000..0777"));
  CHECK_THAT(one_error("cycle: {lock_memory: maybe}"), Catch::Contains("expected true or false"));
  CHECK_THAT(one_error("simulated: {axes: [{frequency_hz: .nan}]}"),
             Catch::Contains("expected a number"));
}

TEST_CASE("cross-field and list rules", "[config]") {
  SECTION("slots default to the position in the list") {
    const ConfigResult r = from("axes: [{name: a}, {name: b}, {name: c}]");
    REQUIRE(r.ok());
    CHECK(r.config().axes[2].slot == 3);
    CHECK(r.config().simulated.axes.size() == 3);
  }
  SECTION("function model 254 takes at most 5 Flatstream bytes by default") {
    const ConfigResult r = from("bus: canio\ncanio: {}\naxes: [{name: a}]");
    INFO(r.error_report());
    REQUIRE(r.ok());
    CHECK(r.config().axes[0].function_model == FunctionModel::BusController);
    CHECK(r.config().axes[0].module.input_mtu == 5);
  }
  SECTION("a real bus needs axes") {
    CHECK_THAT(one_error("bus: canio\ncanio: {}\n"), Catch::Contains("at least one axis"));
  }
  SECTION("powerlink needs an interface") {
    CHECK_THAT(one_error("bus: powerlink\npowerlink: {nodes: [{node_id: 1}]}\naxes: [{node: 1}]"),
               Catch::Contains("powerlink.interface: missing"));
  }
  SECTION("a node entry needs its id") {
    CHECK_THAT(one_error("powerlink: {nodes: [{mandatory: false}]}"),
               Catch::Contains("powerlink.nodes[0].node_id: missing required key"));
  }
  SECTION("sdo overrides") {
    const ConfigResult r =
        from("powerlink: {sdo_overrides: [{register: 4097, index: 0x2001, subindex: 5}]}");
    INFO(r.error_report());
    REQUIRE(r.ok());
    const auto it = r.config().powerlink.sdo_overrides.find(4097);
    REQUIRE(it != r.config().powerlink.sdo_overrides.end());
    CHECK(it->second == std::pair<uint16_t, uint8_t>{0x2001, 5});
    CHECK_THAT(one_error("powerlink: {sdo_overrides: [{register: 4097, index: 2}, "
                         "{register: 4097, index: 3}]}"),
               Catch::Contains("register 4097 is mapped twice (also at line 1)"));
    CHECK_THAT(one_error("powerlink: {sdo_overrides: [{register: 1, index: 2}]}"),
               Catch::Contains("1 is not an X20DS1928 register"));
    CHECK_THAT(one_error("powerlink: {sdo_overrides: [{register: 4097}]}"),
               Catch::Contains("index: missing required key"));
  }
  SECTION("unknown keys without a close match list the allowed keys") {
    CHECK_THAT(one_error("shm: {colour: blue}"),
               Catch::Contains("unknown key 'colour'; allowed keys here: name, mode, group"));
  }
  SECTION("more than one YAML document") {
    CHECK_THAT(one_error("bus: simulated\n---\nbus: canio\n"),
               Catch::Contains("test.yaml:2:1: the file holds more than one YAML document"));
  }
  SECTION("PRes/PReq offset overrides (POWERLINK)") {
    const std::string head =
        "bus: powerlink\npowerlink: {interface: eth1, nodes: [{node_id: 1, preq_size: 60}]}\n";
    const ConfigResult r = from(head +
                                "axes: [{node: 1, slot: 1}, {node: 1, slot: 2, pres_offset: 100, "
                                "preq_offset: 40}]");
    INFO(r.error_report());
    REQUIRE(r.ok());
    CHECK_FALSE(r.config().axes[0].pres_offset);
    CHECK_FALSE(r.config().axes[0].preq_offset);
    CHECK(r.config().axes[1].pres_offset == uint16_t{100});
    CHECK(r.config().axes[1].preq_offset == uint16_t{40});
    // Survives dump_config.
    const ConfigResult again = from(dump_config(r.config()));
    INFO(again.error_report());
    REQUIRE(again.ok());
    CHECK(again.config().axes[1].pres_offset == uint16_t{100});
    // Out of range, past the payload, past the node's preq_size, wrong bus.
    CHECK_THAT(one_error(head + "axes: [{node: 1, pres_offset: 1490}]"),
               Catch::Contains("axes[0].pres_offset: 1490 is out of range 0..1489"));
    CHECK_THAT(one_error(head + "axes: [{node: 1, pres_offset: 1480}]"),
               Catch::Contains("axes[0].pres_offset: PRes block of node 1 slot 1 (bytes "
                               "1480..1502) ends past the PRes payload of 1490 bytes"));
    CHECK_THAT(one_error(head + "axes: [{node: 1, preq_offset: 55}]"),
               Catch::Contains("axes[0].preq_offset: PReq block of node 1 slot 1 (bytes 55..63) "
                               "ends past the PReq payload of 60 bytes"));
    CHECK_THAT(one_error("bus: canio\ncanio: {}\naxes: [{pres_offset: 0}]"),
               Catch::Contains("axes[0].pres_offset: is only meaningful on bus powerlink (the "
                               "bus here is canio)"));
    // A default-placed module is hit by a moved one: reported at the moved one's key.
    CHECK_THAT(one_error(head + "axes: [{node: 1, slot: 1, preq_offset: 9}, {node: 1, slot: 2}]"),
               Catch::Contains("axes[0].preq_offset: PReq block of node 1 slot 1 (bytes 9..17) "
                               "overlaps slot 2 (bytes 9..17) of axes[1]"));
  }
  SECTION("a stray comma at document level") {
    CHECK(one_error(",") ==
          "test.yaml:1:1: YAML syntax error: unexpected ',' (not inside a [list] or {map})");
  }
}

// What differs between the bus kinds comes from one table (src/config/config_bus_kinds.cpp):
// each kind's word, period, function model, node range, empty-axes rule and required section.
TEST_CASE("each bus kind brings its own rules", "[config][bus]") {
  const std::string pl = "bus: powerlink\npowerlink: {interface: eth1, nodes: [{node_id: 1}]}\n";
  SECTION("the word of every kind loads that kind") {
    const std::pair<BusKind, std::string> kinds[] = {
        {BusKind::Simulated, "\n"},
        {BusKind::Powerlink, "\npowerlink: {interface: eth1, nodes: [{node_id: 1}]}\n"},
        {BusKind::Canio, "\ncanio: {}\naxes: [{node: 1}]\n"}};
    for (const auto& [kind, rest] : kinds) {
      const ConfigResult r = from("bus: " + std::string(to_string(kind)) + rest);
      INFO(r.error_report());
      REQUIRE(r.ok());
      CHECK(r.config().bus == kind);
    }
  }
  SECTION("cycle period: 1 ms, CAN-I/O 2 ms") {
    CHECK(from("bus: simulated").config().cycle.period_us == 1000);
    CHECK(from(pl + "axes: [{node: 1}]").config().cycle.period_us == 1000);
    CHECK(from("bus: canio\ncanio: {}\naxes: [{node: 1}]").config().cycle.period_us == 2000);
    CHECK(from("bus: canio\ncanio: {}\ncycle: {period_us: 5000}\naxes: [{node: 1}]")
              .config()
              .cycle.period_us == 5000);
  }
  SECTION("function model: what the bus controller runs") {
    CHECK(one_error("bus: canio\ncanio: {}\naxes: [{function_model: 0}]") ==
          "test.yaml:3:25: axes[0].function_model: 0 is not allowed on bus canio; modules behind "
          "a CAN-I/O bus controller run function model 254");
    CHECK(one_error(pl + "axes: [{node: 1, function_model: 254}]") ==
          "test.yaml:3:34: axes[0].function_model: 254 is not allowed on bus powerlink; modules "
          "behind a POWERLINK bus controller run function model 0");
    const ConfigResult sim = from("axes: [{function_model: 254}, {}]");
    INFO(sim.error_report());
    REQUIRE(sim.ok());
    CHECK(sim.config().axes[0].function_model == FunctionModel::BusController);
    CHECK(sim.config().axes[1].function_model == FunctionModel::Standard);
  }
  SECTION("node numbers: POWERLINK CNs end at 239") {
    CHECK_THAT(one_error(pl + "axes: [{node: 240}]"),
               Catch::EndsWith("axes[0].node: 240 is out of range 1..239"));
    const ConfigResult sim = from("axes: [{node: 255}]");
    INFO(sim.error_report());
    CHECK(sim.ok());
  }
  SECTION("no axes: simulated adds one, powerlink runs without, canio refuses") {
    const ConfigResult sim = from("bus: simulated");
    REQUIRE(sim.ok());
    REQUIRE(sim.config().axes.size() == 1);
    CHECK(sim.config().axes[0].name == "axis0");
    const ConfigResult p = from(pl);
    INFO(p.error_report());
    REQUIRE(p.ok());
    CHECK(p.config().axes.empty());
    CHECK(one_error("bus: canio\ncanio: {}\n") ==
          "test.yaml:1:1: axes: at least one axis is needed on bus canio");
  }
  SECTION("the bus' own section is required, and says what it must give") {
    // (Without a canio section the canio checks used to stop the loader with "cannot interpret
    // the document: invalid node" besides this error.)
    CHECK(one_error("bus: canio\naxes: [{node: 1}]") ==
          "test.yaml:1:6: bus: bus is 'canio' but the file has no canio section (interface, "
          "bitrate)");
    CHECK(one_error("bus: powerlink\naxes: [{node: 1}]") ==
          "test.yaml:1:6: bus: bus is 'powerlink' but the file has no powerlink section "
          "(interface, nodes)");
  }
}

TEST_CASE("dump_config round-trips", "[config]") {
  for (const char* file : {"simulated.yaml", "powerlink.yaml", "canio.yaml"}) {
    const ConfigResult first = load_config(kSource + "/config/" + file);
    REQUIRE(first.ok());
    const std::string text = dump_config(first.config());
    const ConfigResult second = load_config_from_string(text, first.config().source_file);
    INFO(text << second.error_report());
    REQUIRE(second.ok());
    CHECK(dump_config(second.config()) == text);
  }
}

TEST_CASE("encoder files are resolved against the config file", "[config]") {
  const auto dir =
      std::filesystem::temp_directory_path() / ("ds1928-config-test-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "enc.yaml") << "{}\n";
  std::ofstream(dir / "good.yaml") << "simulated: {axes: [{encoder_file: enc.yaml}]}\n";
  std::ofstream(dir / "bad.yaml") << "simulated:\n  axes:\n    - encoder_file: missing.yaml\n";
  const ConfigResult good = load_config((dir / "good.yaml").string());
  INFO(good.error_report());
  REQUIRE(good.ok());
  CHECK(good.config().simulated.axes[0].encoder_file == (dir / "enc.yaml").string());
  const ConfigResult bad = load_config((dir / "bad.yaml").string());
  REQUIRE(bad.errors().size() == 1);
  CHECK(bad.errors()[0].line == 3);
  CHECK(bad.errors()[0].key == "simulated.axes[0].encoder_file");
  CHECK_THAT(bad.errors()[0].message, Catch::Contains("no such file"));
  std::filesystem::remove_all(dir);
}

TEST_CASE("unreadable files are an error without a position", "[config]") {
  const ConfigResult r = load_config(kBad + "does-not-exist.yaml");
  REQUIRE(r.errors().size() == 1);
  CHECK(r.errors()[0].line == 0);
  CHECK(r.errors()[0].to_string() == kBad + "does-not-exist.yaml: cannot open the file");
}

TEST_CASE("socket fallback path", "[config]") {
  const char* old = std::getenv("XDG_RUNTIME_DIR");
  const std::string saved = old ? old : "";
  ::setenv("XDG_RUNTIME_DIR", "/run/user/1000", 1);
  CHECK(fallback_socket_path("/run/ds1928d/control.sock") == "/run/user/1000/ds1928d/control.sock");
  ::unsetenv("XDG_RUNTIME_DIR");
  CHECK(fallback_socket_path("/run/ds1928d/control.sock") ==
        "/tmp/ds1928d-" + std::to_string(::getuid()) + "/control.sock");
  if (old) ::setenv("XDG_RUNTIME_DIR", saved.c_str(), 1);
}

TEST_CASE("mutated files never crash the loader and every error is located", "[config][fuzz]") {
  std::ifstream in(kSource + "/config/powerlink.yaml");
  const std::string original((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  REQUIRE(original.size() > 100);
  uint64_t state = 0x9E3779B97F4A7C15ull;  // fixed seed: failures reproduce
  const auto next = [&state] {
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
  };
  const std::string alphabet = " \n:-[]{}#'\"0x19aZ_.,&*!|>\t";
  size_t rejected = 0;
  for (int round = 0; round < 2000; ++round) {
    std::string text = original;
    const int edits = 1 + static_cast<int>(next() % 4);
    for (int e = 0; e < edits; ++e) {
      const size_t pos = next() % text.size();
      switch (next() % 3) {
        case 0:
          text[pos] = alphabet[next() % alphabet.size()];
          break;
        case 1:
          text.erase(pos, 1 + next() % 8);
          break;
        default:
          text.insert(pos, 1, alphabet[next() % alphabet.size()]);
          break;
      }
      if (text.empty())
        text.push_back('x');  // not `= "x"`: GCC 12 -O3 false -Wrestrict (PR 105329)
    }
    const ConfigResult r = load_config_from_string(text, "mutated.yaml");
    if (r.ok()) continue;
    ++rejected;
    for (const auto& err : r.errors()) {
      INFO(text << "\n" << err.to_string());
      CHECK(err.line > 0);
      CHECK_FALSE(err.message.empty());
    }
  }
  CHECK(rejected > 500);  // the mutations must actually exercise the error paths
}

TEST_CASE("a file is read up to 1 MiB, devices and unreadable files say why", "[config]") {
  for (const char* endless : {"/dev/zero", "/dev/urandom"}) {
    const ConfigResult r = load_config(endless);
    REQUIRE(r.errors().size() == 1);
    CHECK_THAT(r.errors().front().message, Catch::Contains("larger than 1048576 bytes"));
  }
  const auto big = std::filesystem::temp_directory_path() /
                   ("ds1928-config-big-" + std::to_string(getpid()) + ".yaml");
  {
    std::ofstream f(big);
    f << "# " << std::string(1048576, 'x') << "\n";
  }
  const ConfigResult r = load_config(big.string());
  std::filesystem::remove(big);
  REQUIRE(r.errors().size() == 1);
  CHECK_THAT(r.errors().front().message, Catch::Contains("larger than 1048576 bytes"));

  // stat calls /proc/self/mem a regular file of size 0; reading it fails.
  CHECK_THAT(one_error("simulated:\n  axes: [{encoder_file: /proc/self/mem}]\naxes: [{name: x}]\n"),
             Catch::Contains("cannot read /proc/self/mem"));
  CHECK_THAT(one_error("simulated:\n  axes: [{encoder_file: /tmp}]\naxes: [{name: x}]\n"),
             Catch::Contains("not a regular file: /tmp is a directory"));
}

TEST_CASE("metrics section: listen address, off, limits", "[config]") {
  const ConfigResult d = from("{}");
  REQUIRE(d.ok());
  REQUIRE(d.config().metrics.listen);
  CHECK(d.config().metrics.listen->address == "127.0.0.1");
  CHECK(d.config().metrics.listen->port == 9928);
  CHECK(d.config().metrics.max_connections == 64u);

  const ConfigResult off = from("metrics: {listen: 'off'}");
  REQUIRE(off.ok());
  CHECK_FALSE(off.config().metrics.listen);
  CHECK(from(dump_config(off.config())).ok());

  const ConfigResult v6 = from("metrics: {listen: '[::1]:9100', timeout_ms: 200}");
  REQUIRE(v6.ok());
  CHECK(v6.config().metrics.listen->address == "::1");
  CHECK(v6.config().metrics.timeout_ms == 200u);
  CHECK(dump_config(from(dump_config(v6.config())).config()) == dump_config(v6.config()));

  CHECK_THAT(one_error("metrics: {listen: 'localhost:9928'}"),
             Catch::Contains("'localhost:9928' is neither 'off' nor an address"));
  CHECK_THAT(one_error("metrics: {max_connections: 0}"), Catch::Contains("max_connections"));
  CHECK_THAT(one_error("metrics: {port: 1}"), Catch::Contains("port"));
}

TEST_CASE("capture limits: defaults, values, a ring that is not a power of two", "[config]") {
  const ConfigResult d = load_config_from_string("{}\n", "test.yaml");
  REQUIRE(d.ok());
  CHECK(d.config().capture.ring_frames == 4096);
  CHECK(d.config().capture.max_duration_s == 3600);
  CHECK(d.config().capture.max_bytes == 1024ULL * 1048576);
  const ConfigResult set = load_config_from_string(
      "capture: {ring_frames: 1024, max_duration_s: 60, max_bytes: 1000000}\n", "test.yaml");
  INFO(set.error_report());
  REQUIRE(set.ok());
  CHECK(set.config().capture.ring_frames == 1024);
  CHECK(set.config().capture.max_duration_s == 60);
  CHECK(set.config().capture.max_bytes == 1000000);
  const ConfigResult bad = load_config_from_string("capture: {ring_frames: 1000}\n", "test.yaml");
  REQUIRE(bad.errors().size() == 1);
  CHECK(bad.errors()[0].key == "capture.ring_frames");
  CHECK_THAT(bad.errors()[0].message, Catch::Contains("power of two"));
}

// Every axes[].module range is the object dictionary's (docs/registers.md): one value past each end
// of what the register accepts is refused, each end itself is taken, in both function models.
TEST_CASE("module settings accept exactly the object dictionary's range", "[config]") {
  struct Key {
    const char* key;
    Setting setting;
  };
  const Key keys[] = {{"prescaler", Setting::Prescaler},
                      {"vss_min_mv", Setting::VssMin},
                      {"vss_max_mv", Setting::VssMax},
                      {"quit_time_us", Setting::QuitTime},
                      {"output_mtu", Setting::OutputMtu},
                      {"input_mtu", Setting::InputMtu},
                      {"flatstream_mode", Setting::FlatstreamMode},
                      {"forward", Setting::Forward},
                      {"forward_delay_us", Setting::ForwardDelay},
                      {"error_enable", Setting::ErrorEnable}};
  for (const FunctionModel fm : {FunctionModel::Standard, FunctionModel::BusController}) {
    const RegisterInfo* reg = nullptr;
    for (const Key& k : keys) {
      for (const RegisterInfo& r : object_dictionary())
        if (!r.view && r.setting == k.setting) reg = &r;
      REQUIRE(reg != nullptr);
      const ValueRange accepted = reg->accepts(fm);
      const std::string head =
          std::string("bus: simulated\naxes:\n  - name: x\n    function_model: ") +
          (fm == FunctionModel::Standard ? "0" : "254") + "\n    module: {";
      // vss_min must not exceed vss_max: test each against the other's widest value.
      const std::string partner = k.setting == Setting::VssMin   ? ", vss_max_mv: 1500"
                                  : k.setting == Setting::VssMax ? ", vss_min_mv: 0"
                                                                 : "";
      auto with = [&](int64_t v) {
        return head + k.key + ": " + std::to_string(v) + partner + "}\n";
      };
      INFO(k.key << " under function model " << static_cast<int>(fm));
      for (const int64_t v : {int64_t{accepted.min}, int64_t{accepted.max}}) {
        const ConfigResult r = load_config_from_string(with(v));
        INFO(r.error_report());
        CHECK(r.ok());
      }
      const std::string range = std::to_string(accepted.min) + ".." + std::to_string(accepted.max);
      if (accepted.min > 0) {
        const ConfigResult r = load_config_from_string(with(int64_t{accepted.min} - 1));
        REQUIRE_FALSE(r.ok());
        CHECK_THAT(r.error_report(), Catch::Contains("is out of range " + range));
      }
      const ConfigResult r = load_config_from_string(with(int64_t{accepted.max} + 1));
      REQUIRE_FALSE(r.ok());
      CHECK_THAT(r.error_report(), Catch::Contains("is out of range " + range));
    }
  }
}

TEST_CASE("cycle.timebase: monotonic by default, tai on request, nothing else", "[config]") {
  const ConfigResult def = from("bus: simulated\n");
  REQUIRE(def.ok());
  CHECK(def.config().cycle.timebase == TimebaseKind::Monotonic);
  const ConfigResult tai = from("bus: simulated\ncycle: {timebase: tai}\n");
  REQUIRE(tai.ok());
  CHECK(tai.config().cycle.timebase == TimebaseKind::Tai);
  CHECK_THAT(dump_config(tai.config()), Catch::Contains("  timebase: tai\n"));
  CHECK_THAT(one_error("cycle: {timebase: ptp}"),
             Catch::Contains("expected one of: monotonic, tai"));
}

TEST_CASE("axes[].invalidate_on: per error bit by the table's names", "[config][errors]") {
  const ConfigResult r = from(
      "axes: [{name: a, invalidate_on: {EnDatRefWarning: true, Battery: false, "
      "Temperature: true}}]");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const AxisConfig& a = r.config().axes[0];
  CHECK(a.invalidate_on[0] == 0x80);  // ErrorInfo bit 7
  CHECK(a.invalidate_on[2] == 0x02);  // EnDatWarning bit 1
  CHECK(a.flag_only_on[1] == 0x40);   // EnDatError bit 6
  const ErrorPolicy p = a.error_policy();
  CHECK((p.invalidate[0] & 0x80) != 0);
  CHECK((p.invalidate[1] & 0x40) == 0);
  // Survives dump_config.
  const ConfigResult again = from(dump_config(r.config()));
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(again.config().axes[0].invalidate_on == a.invalidate_on);
  CHECK(again.config().axes[0].flag_only_on == a.flag_only_on);
  // An unknown bit and a non-boolean are named.
  CHECK_THAT(one_error("axes: [{invalidate_on: {EnDatRefWarnin: true}}]"),
             Catch::Contains("unknown key 'EnDatRefWarnin' (did you mean 'EnDatRefWarning'?)"));
  CHECK_THAT(one_error("axes: [{invalidate_on: {Battery: sometimes}}]"),
             Catch::Contains("expected true or false"));
}

TEST_CASE("axes[].info: the channels by name or raw, written as EnDatInfoCmd01..04",
          "[config][info]") {
  const ConfigResult r = from(
      "axes: [{name: a, info: [temperature1, {name: pos2, info: position2_word1}, "
      "{name: scale, command: 0x06, mrs: 0xA5, block: 1, parameter: 3}, "
      "{name: delta, command: 0x09, mrs: 0x52, signed: true}]}]");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const AxisConfig& a = r.config().axes[0];
  REQUIRE(a.info.size() == 4);
  CHECK(a.info[0].name == "temperature1");
  CHECK(a.info[0].request == InfoRequest{0x08, 0x4C, 0, std::nullopt});
  CHECK(a.info[1].name == "pos2");
  CHECK(a.info[1].request.mrs == 0x42);
  CHECK(a.info[3].is_signed);
  // §11.8.3.1: command, MRS, then parameter (unblocked) or block and parameter (blocked).
  CHECK(a.module.info_cmd[0] == 0x0000'4C08u);
  CHECK(a.module.info_cmd[1] == 0x0000'4208u);
  CHECK(a.module.info_cmd[2] == 0x0301'A506u);
  CHECK(a.module.info_cmd[3] == 0x0000'5209u);
  CHECK(from("axes: [{name: a}]").config().axes[0].module.info_cmd == std::array<uint32_t, 4>{});
  // Survives dump_config.
  const ConfigResult again = from(dump_config(r.config()));
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(again.config().axes[0].module.info_cmd == a.module.info_cmd);
  CHECK(again.config().axes[0].info[3].is_signed);
  CHECK(again.config().axes[0].info[2].name == "scale");
}

TEST_CASE("axes[].info: a bad channel is named precisely", "[config][info]") {
  CHECK_THAT(one_error("axes: [{info: [temprature1]}]"),
             Catch::Contains("'temprature1' is not a known additional information"));
  CHECK_THAT(one_error("axes: [{info: [a, b, c, d, e]}]"),
             Catch::Contains("5 entries; the module has 4 channels"));
  CHECK_THAT(one_error("axes: [{info: [{name: t, command: 0x08, mrs: 0xA5}]}]"),
             Catch::Contains("MRS code 0x40..0x5E"));
  CHECK_THAT(one_error("axes: [{info: [{name: t, command: 0x06, mrs: 0xA5, parameter: 1}]}]"),
             Catch::Contains("a block is needed"));
  CHECK_THAT(one_error("axes: [{info: [{name: t, command: 0x02, mrs: 0xA5}]}]"),
             Catch::Contains("command must be 0x04, 0x06 or 0x08..0x0B"));
  CHECK_THAT(one_error("axes: [{info: [{command: 0x08, mrs: 0x4C}]}]"),
             Catch::Contains("a map entry needs a name"));
  CHECK_THAT(one_error("axes: [{info: [temperature1, temperature1]}]"),
             Catch::Contains("channel name 'temperature1' is used twice"));
  CHECK_THAT(one_error("axes: [{info: [{name: t, info: temperature1, mrs: 0x4D}]}]"),
             Catch::Contains("not with info"));
  CHECK_THAT(one_error("axes: [{info: [{name: 't x', info: temperature1}]}]"),
             Catch::Contains("is not a valid name"));
}
