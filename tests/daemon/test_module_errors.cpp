// The module's error bits end to end, in-process and deterministic: simulated module (its faults)
// → the simulated bus → CycleWork (decode, validity by class) → shared memory (validity, flags,
// the held position) → status JSON, metrics and journal records by bit name. The cycles run on
// the test's thread, one at a time, and the test steps the modules' time itself (no sleeps).
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <string>

#include "cycle_work.hpp"
#include "ds1928/shm.hpp"
#include "metrics/exposition.hpp"
#include "module_errors.hpp"
#include "module_leds.hpp"
#include "sim/simulated_bus.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;

namespace {

class Bench {
 public:
  Bench() {
    static int serial = 0;
    config.cycle.period_us = 1000;
    AxisConfig axis;
    axis.name = "x";
    axis.module.endat_enable = true;
    config.axes.push_back(axis);
    config.shm.name = "/ds1928-errors-" + std::to_string(getpid()) + "-" + std::to_string(++serial);
    bus = std::make_unique<sim::SimulatedBus>(config.axes, config.simulated);
    REQUIRE_FALSE(bus->start());
    REQUIRE_FALSE(publisher.open(config.shm, 1, 1'000'000));
    work = std::make_unique<CycleWork>(config, *bus, publisher);
    REQUIRE_FALSE(reader.open(config.shm.name));
  }
  ~Bench() { publisher.close(); }
  // Runs `n` cycles of 1 ms: the simulated bus ticks its modules on the cycle's start time, so
  // exactly n ms of module time pass, whatever the machine's load.
  ds1928_axis_data run(int n) {
    for (int i = 0; i < n; ++i) {
      CycleContext ctx;
      ctx.index = ++index_;
      ctx.start_ns = t0_ + static_cast<int64_t>(index_) * 1'000'000;
      ctx.woke_ns = ctx.start_ns;
      work->run_cycle(ctx);
    }
    ds1928_axis_data d{};
    REQUIRE_FALSE(reader.read(0, d));
    return d;
  }
  sim::Ds1928Module& module() { return bus->module(0); }
  // One register access through the bus's register path, served in the next cycle.
  uint32_t access(uint16_t reg, bool write = false, uint32_t value = 0) {
    RegisterRequest r;
    r.tag = ++tag_;
    r.reg = reg;
    r.size = write ? 1 : 2;
    r.write = write;
    r.value = value;
    REQUIRE(bus->submit(r));
    run(1);
    RegisterResult out;
    REQUIRE(bus->poll(out));
    REQUIRE(out.tag == r.tag);
    REQUIRE_FALSE(out.error);
    return out.value;
  }
  // What the EnDat service does every second: EnDatError and EnDatWarning into the counters.
  void read_encoder_words() {
    work->counters(0).endat_error.store(static_cast<uint16_t>(access(reg::kEnDatError)));
    work->counters(0).endat_warning.store(static_cast<uint16_t>(access(reg::kEnDatWarning)));
  }

  DaemonConfig config;
  std::unique_ptr<sim::SimulatedBus> bus;
  shm::Publisher publisher;
  std::unique_ptr<CycleWork> work;
  ShmReader reader;

 private:
  uint64_t index_ = 0;
  uint32_t tag_ = 0;
  int64_t t0_ = 1'000'000'000;
};

// The simulated bus as the daemon's services see it (the default node phase: the driver's state).
struct SimView final : BusService {
  explicit SimView(BusDriver& d) : bus(d) {}
  BusDriver& driver() noexcept override { return bus; }
  BusDriver& bus;
};

// The error class the module's e-LED would flash, as `status` says it.
std::string e_class(Bench& b) {
  SimView view(*b.bus);
  const ModuleLeds m = module_leds(view, *b.work, b.config, 0);
  CHECK(m.state == ModuleState::Run);
  return std::string(to_string(m.error_class));
}

std::string metrics_of(Bench& b) {
  metrics::Exposition out(metrics::Format::Prometheus);
  append_module_error_metrics(out, b.config, *b.work);
  return out.finish();
}

}  // namespace

TEST_CASE(
    "error classes end to end: a warning stays valid, an analogue error holds the last "
    "good position stale, a fault is module_error",
    "[errors][e2e]") {
  Bench b;
  ds1928_axis_data d = b.run(300);
  REQUIRE(d.validity == DS1928_AXIS_VALID);
  CHECK((d.flags & (DS1928_AXIS_FAULT | DS1928_AXIS_WARNING | DS1928_AXIS_HELD)) == 0);
  CHECK(e_class(b) == "none");

  // Warning: EnDatRefWarning. Flagged, the position moves on and stays valid.
  b.module().inject_error(error_info::kEnDatRefWarning);
  const ds1928_axis_data before = b.run(1);
  d = b.run(20);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK((d.flags & DS1928_AXIS_WARNING) != 0);
  CHECK((d.flags & DS1928_AXIS_FAULT) == 0);
  CHECK(d.error_info == error_info::kEnDatRefWarning);
  CHECK(d.position_raw != before.position_raw);
  CHECK(e_class(b) == "io");  // reference: single flash
  const nlohmann::json bits =
      error_bits_json(error_words(b.work->counters(0)), b.config.axes[0].error_policy());
  REQUIRE(bits.size() == 1);
  CHECK(bits[0]["name"] == "EnDatRefWarning");
  CHECK(bits[0]["class"] == "warning");
  CHECK(bits[0]["effect"] == "flag");
  CHECK(bits[0]["remedy"].get<std::string>().find("referenced again") != std::string::npos);
  std::string text = metrics_of(b);
  CHECK(text.find("ds1928_axis_module_error{axis=\"0\",name=\"x\",register=\"ErrorInfo\","
                  "bit=\"EnDatRefWarning\",class=\"warning\"} 1") != std::string::npos);
  CHECK(text.find("bit=\"VssCheckError\",class=\"fault\"} 0") != std::string::npos);
  // Acknowledged (AckErrorInfo bit 7 through the cycle's command queue): gone.
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, error_info::kEnDatRefWarning}));
  d = b.run(20);
  CHECK(d.error_info == 0);
  CHECK((d.flags & DS1928_AXIS_WARNING) == 0);

  // Analogue error: the amplitude leaves the Vss window. The module holds (PosCycle stands); the
  // daemon publishes the last good position as stale with the HELD flag.
  const ds1928_axis_data good = b.run(1);
  REQUIRE(good.validity == DS1928_AXIS_VALID);
  b.module().set_vss_mv(300);
  d = b.run(30);
  CHECK(d.validity == DS1928_AXIS_STALE);
  CHECK((d.flags & DS1928_AXIS_HELD) != 0);
  CHECK((d.flags & DS1928_AXIS_FAULT) != 0);
  CHECK((d.error_info & error_info::kVssCheckError) != 0);
  CHECK(d.position_raw == good.position_raw);
  CHECK(b.work->counters(0).held.load() > 0);
  CHECK(e_class(b) == "io");  // sin/cos amplitude (wire break): single flash
  // Amplitude good again, acknowledged: after SinCosQuitTime (100 ms) positions flow again.
  b.module().set_vss_mv(1000);
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, error_info::kVssCheckError}));
  d = b.run(150);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK((d.flags & DS1928_AXIS_HELD) == 0);
  CHECK(d.position_raw != good.position_raw);

  // Fault: EnDatComError → module_error.
  b.module().inject_error(error_info::kEnDatComError);
  d = b.run(5);
  CHECK(d.validity == DS1928_AXIS_MODULE_ERROR);
  CHECK((d.flags & DS1928_AXIS_FAULT) != 0);
  CHECK(e_class(b) == "system");  // EnDat communication: double flash
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, error_info::kEnDatComError}));
  d = b.run(20);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK(e_class(b) == "none");

  // The encoder's words (read acyclically by the EnDat service into the counters): an EnDatWarning
  // bit is a warning, an EnDatError bit a fault.
  b.work->counters(0).endat_warning.store(0x0002);  // Temperature
  d = b.run(2);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK((d.flags & DS1928_AXIS_WARNING) != 0);
  CHECK(d.endat_warning == 0x0002);
  b.work->counters(0).endat_error.store(0x0040);  // Battery
  d = b.run(2);
  CHECK(d.validity == DS1928_AXIS_MODULE_ERROR);
  text = metrics_of(b);
  CHECK(text.find("register=\"EnDatError\",bit=\"Battery\",class=\"fault\"} 1") !=
        std::string::npos);
  CHECK(text.find("register=\"EnDatWarning\",bit=\"Temperature\",class=\"warning\"} 1") !=
        std::string::npos);
  // The encoder's own words light nothing on the module (its ErrorInfo is clear).
  CHECK(e_class(b) == "none");
}

TEST_CASE(
    "the simulated encoder's own words end to end: a warning stays valid, an error is "
    "module_error, both clear after EnDatAck, and a low encoder supply is module_error",
    "[errors][e2e]") {
  Bench b;
  REQUIRE(b.run(300).validity == DS1928_AXIS_VALID);
  sim::EnDatEncoder& encoder = b.module().endat().encoder();
  // Temperature exceeded (EnDatWarning bit 1): the module's status refresh (0.5 s) mirrors it.
  encoder.set_warning_conditions(0x0002);
  b.run(1200);
  b.read_encoder_words();
  const ds1928_axis_data before = b.run(1);
  ds1928_axis_data d = b.run(5);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK(d.endat_warning == 0x0002);
  CHECK((d.flags & DS1928_AXIS_WARNING) != 0);
  CHECK((d.flags & DS1928_AXIS_FAULT) == 0);
  CHECK(d.position_raw != before.position_raw);
  std::string text = metrics_of(b);
  CHECK(text.find("register=\"EnDatWarning\",bit=\"Temperature\",class=\"warning\"} 1") !=
        std::string::npos);
  // Light source failed (EnDatError bit 0): F1 in the next position frame → EnDatPosError.
  encoder.set_error_conditions(0x0001);
  d = b.run(5);
  CHECK(d.validity == DS1928_AXIS_MODULE_ERROR);
  CHECK((d.error_info & error_info::kEnDatPosError) != 0);
  b.run(1200);
  b.read_encoder_words();
  d = b.run(2);
  CHECK(d.endat_error == 0x0001);
  const nlohmann::json bits =
      error_bits_json(error_words(b.work->counters(0)), b.config.axes[0].error_policy());
  CHECK(std::any_of(bits.begin(), bits.end(), [](const nlohmann::json& j) {
    return j["name"] == "Lighting" && j["class"] == "fault" && j["effect"] == "module_error";
  }));
  text = metrics_of(b);
  CHECK(text.find("register=\"EnDatError\",bit=\"Lighting\",class=\"fault\"} 1") !=
        std::string::npos);
  // Both conditions gone: the words stay until EnDatAck bit 0, ErrorInfo until AckErrorInfo.
  encoder.set_error_conditions(0);
  encoder.set_warning_conditions(0);
  b.run(1200);
  b.read_encoder_words();
  CHECK(b.run(2).endat_error == 0x0001);
  (void)b.access(reg::kEnDatAck, true, 0x01);
  b.run(1200);
  b.read_encoder_words();
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, error_info::kEnDatPosError}));
  d = b.run(20);
  CHECK(d.endat_error == 0);
  CHECK(d.endat_warning == 0);
  CHECK(d.error_info == 0);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK((d.flags & (DS1928_AXIS_FAULT | DS1928_AXIS_WARNING)) == 0);
  // The encoder supply drops below 4750 mV: EncoderSupplyError, a fault.
  b.module().set_supply_mv(4500);
  d = b.run(5);
  CHECK(d.validity == DS1928_AXIS_MODULE_ERROR);
  CHECK(d.error_info == error_info::kEncoderSupplyError);
  b.module().set_supply_mv(5000);
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, error_info::kEncoderSupplyError}));
  CHECK(b.run(20).validity == DS1928_AXIS_VALID);
}

TEST_CASE("axes[].invalidate_on overrides the class per bit", "[errors][e2e]") {
  Bench b;
  DaemonConfig& c = b.config;
  // A new CycleWork with the override: EnDatRefWarning invalidates, EnDatComError only flags.
  c.axes[0].invalidate_on[0] = error_info::kEnDatRefWarning;
  c.axes[0].flag_only_on[0] = error_info::kEnDatComError;
  b.work = std::make_unique<CycleWork>(c, *b.bus, b.publisher);
  REQUIRE(b.run(300).validity == DS1928_AXIS_VALID);
  b.module().inject_error(error_info::kEnDatRefWarning);
  CHECK(b.run(5).validity == DS1928_AXIS_MODULE_ERROR);
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, error_info::kEnDatRefWarning}));
  REQUIRE(b.run(20).validity == DS1928_AXIS_VALID);
  b.module().inject_error(error_info::kEnDatComError);
  const ds1928_axis_data d = b.run(5);
  CHECK(d.validity == DS1928_AXIS_VALID);
  CHECK((d.flags & DS1928_AXIS_FAULT) != 0);
}

TEST_CASE("the journal gets one record per change of an axis' error bits, with their names",
          "[errors][journal]") {
  Bench b;
  auto sink = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(64);
  auto previous = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("test", sink));
  ErrorJournal journal(1);
  b.run(300);
  journal.poll(b.config, *b.work, "simulated");
  journal.poll(b.config, *b.work, "simulated");
  CHECK(sink->last_formatted().empty());  // nothing set, nothing changed
  b.module().inject_error(error_info::kEnDatRefWarning | error_info::kEnDatComError);
  b.run(5);
  journal.poll(b.config, *b.work, "simulated");
  journal.poll(b.config, *b.work, "simulated");  // no change: no second record
  REQUIRE(b.work->post({AxisCommand::Kind::AckErrors, 0, 0xFF}));
  b.run(20);
  journal.poll(b.config, *b.work, "simulated");
  const auto lines = sink->last_formatted();
  spdlog::set_default_logger(previous);
  REQUIRE(lines.size() == 2);
  CHECK(lines[0].find("error bits EnDatComError,EnDatRefWarning") != std::string::npos);
  CHECK(lines[0].find("came: EnDatComError,EnDatRefWarning") != std::string::npos);
  CHECK(lines[1].find("error bits none") != std::string::npos);
  CHECK(lines[1].find("went: EnDatComError,EnDatRefWarning") != std::string::npos);
}
