// The simulated X20DS1928 against the datasheet's register behaviour (X20DS1928.md §2–§5).
#include <catch2/catch.hpp>

#include "sim/ds1928_module.hpp"
#include "sim/sim_error.hpp"
#include "sim/simulated_bus.hpp"

using namespace ds1928;
using sim::Ds1928Module;

namespace {
constexpr int64_t kUs = 1000;

SimAxisConfig constant(double v) {
  SimAxisConfig c;
  c.profile = MotionProfile::ConstantVelocity;
  c.velocity_periods_per_s = v;
  c.module_cycle_us = 100;
  return c;
}

// Runs the module for `ticks` system ticks of 100 µs, one bus cycle per tick.
int count_pos_cycle_changes(Ds1928Module& m, int ticks, int64_t& t) {
  int changes = 0;
  int8_t last = m.inputs().pos_cycle;
  for (int i = 0; i < ticks; ++i) {
    t += 100 * kUs;
    m.tick(t, static_cast<uint64_t>(t / kUs));
    if (m.inputs().pos_cycle != last) ++changes;
    last = m.inputs().pos_cycle;
  }
  return changes;
}
void step(Ds1928Module& m, int64_t& t) {
  t += 100 * kUs;
  m.tick(t, static_cast<uint64_t>(t / kUs));
}
}  // namespace

TEST_CASE("power-up applies the bus-controller defaults: EnDat disabled, no positions", "[sim]") {
  Ds1928Module m(FunctionModel::BusController, constant(100));
  uint32_t v = 99;
  REQUIRE_FALSE(m.read_register(reg::kEnDatMode, 1, v));
  CHECK(v == 0);
  REQUIRE_FALSE(m.read_register(reg::kSystemCyclePrescaler, 2, v));
  CHECK(v == 2);
  REQUIRE_FALSE(m.read_register(reg::kSlframeGenId, 1, v));
  CHECK(v == 14);
  REQUIRE_FALSE(m.read_register(reg::kSinCosVssMax, 2, v));
  CHECK(v == 1200);
  int64_t t = 0;
  CHECK(count_pos_cycle_changes(m, 100, t) == 0);  // EnDatMode bit 0 gates the encoder
  CHECK(m.inputs().position_lw == 0);
}

TEST_CASE("PosCycle advances once per EnDat cycle = module cycle x prescaler", "[sim]") {
  for (uint16_t prescaler : {2, 4, 8}) {
    Ds1928Module m(FunctionModel::Standard, constant(100));
    REQUIRE_FALSE(m.write_register(reg::kSystemCyclePrescaler, 2, prescaler));
    REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
    int64_t t = 0;
    (void)count_pos_cycle_changes(m, 8, t);  // settle on the grid
    CHECK(count_pos_cycle_changes(m, 800, t) == 800 / prescaler);
  }
}

TEST_CASE("positions follow the profile in the sin/cos fixed-point format, low 3 bits 0", "[sim]") {
  Ds1928Module m(FunctionModel::Standard, constant(1000.0));  // 1000 periods/s
  REQUIRE_FALSE(m.write_register(reg::kSystemCyclePrescaler, 2, 2));
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  int64_t t = 0;
  for (int i = 0; i < 10000; ++i) {  // 1 s
    t += 100 * kUs;
    m.tick(t, static_cast<uint64_t>(t / kUs));
    const auto in = m.inputs();
    REQUIRE((in.position_lw & 7u) == 0);
  }
  const auto in = m.inputs();
  const uint64_t raw = (uint64_t{in.position_hw} << 32) | in.position_lw;
  const double periods = static_cast<double>(raw) / 65536.0;
  CHECK(periods == Approx(1000.0).margin(0.25));  // within one EnDat cycle (200 µs = 0.2 periods)
  // PosTime is the NetTime of the acquisition instant: never in the future, at most one EnDat
  // cycle in the past.
  const uint32_t now_us = static_cast<uint32_t>(t / kUs);
  CHECK(static_cast<int32_t>(now_us - in.pos_time_us) >= 0);
  CHECK(static_cast<int32_t>(now_us - in.pos_time_us) < 200);
}

TEST_CASE("SDCLifeCount counts system ticks (function model 0 only)", "[sim]") {
  Ds1928Module m(FunctionModel::Standard, constant(1));
  int64_t t = 0;
  m.tick(t, 0);
  const int8_t start = m.inputs().sdc_life_count;
  for (int i = 0; i < 300; ++i) {
    t += 100 * kUs;
    m.tick(t, static_cast<uint64_t>(t / kUs));
  }
  CHECK(static_cast<int8_t>(m.inputs().sdc_life_count - start) == static_cast<int8_t>(300));
  Ds1928Module b(FunctionModel::BusController, constant(1));
  b.tick(0, 0);
  b.tick(30'000 * kUs, 30'000);
  CHECK(b.inputs().sdc_life_count == 0);
}

TEST_CASE("an injected fault stays in ErrorInfo until AckErrorInfo acknowledges it", "[sim]") {
  Ds1928Module m(FunctionModel::Standard, constant(1));
  m.inject_error(error_info::kEnDatComError | error_info::kVssCheckError);
  int64_t t = 0;
  for (int i = 0; i < 50; ++i) step(m, t);
  CHECK(m.inputs().error_info == (error_info::kEnDatComError | error_info::kVssCheckError));
  ModuleOutputs out;
  out.ack_error_info = error_info::kEnDatComError;  // acknowledge one of the two
  m.apply_outputs(out);
  step(m, t);
  CHECK(m.inputs().error_info == error_info::kVssCheckError);
  // Holding the ack bit does not acknowledge a fault that appears later: it acts on the edge.
  m.inject_error(error_info::kEnDatComError);
  m.apply_outputs(out);
  step(m, t);
  CHECK((m.inputs().error_info & error_info::kEnDatComError) != 0);
  out.ack_error_info = 0;
  m.apply_outputs(out);
  out.ack_error_info = 0xFF;
  m.apply_outputs(out);
  CHECK(m.inputs().error_info == 0);
}

TEST_CASE("ErrorEnable masks detection of ErrorInfo bits", "[sim]") {
  Ds1928Module m(FunctionModel::Standard, constant(1));
  REQUIRE_FALSE(m.write_register(reg::kErrorEnable, 1, 0xFF & ~error_info::kEnDatPosError));
  m.inject_error(error_info::kEnDatPosError | error_info::kEncoderSupplyError);
  m.tick(0, 0);
  CHECK(m.inputs().error_info == error_info::kEncoderSupplyError);
}

TEST_CASE("acyclic register access rejects bad registers, sizes and values by name", "[sim]") {
  Ds1928Module m(FunctionModel::BusController, constant(1));
  CHECK(m.write_register(reg::kOutputMtu, 1, 6) == sim::SimErrc::out_of_range);  // > 5 on model 254
  CHECK_FALSE(m.write_register(reg::kOutputMtu, 1, 5));
  CHECK(m.write_register(reg::kForward, 1, 8) == sim::SimErrc::out_of_range);
  CHECK(m.write_register(reg::kSystemCyclePrescaler, 1, 2) == sim::SimErrc::wrong_size);
  CHECK(m.write_register(reg::kSystemCyclePrescaler, 2, 1) == sim::SimErrc::out_of_range);
  CHECK(m.write_register(reg::kSinCosEnable, 1, 0) == sim::SimErrc::out_of_range);
  CHECK(m.write_register(reg::kEnDatError, 2, 0) == sim::SimErrc::read_only);
  CHECK(m.write_register(12345, 1, 0) == sim::SimErrc::unknown_register);
  uint32_t v = 0;
  CHECK(m.read_register(12345, 1, v) == sim::SimErrc::unknown_register);
  Ds1928Module fm0(FunctionModel::Standard, constant(1));
  CHECK_FALSE(fm0.write_register(reg::kOutputMtu, 1, 15));
}

TEST_CASE("the simulated bus configures modules at start and answers acyclic requests in the cycle",
          "[sim]") {
  DaemonConfig cfg;
  cfg.axes.resize(2);
  cfg.axes[1].module.prescaler = 4;
  sim::SimulatedBus bus(cfg);
  REQUIRE_FALSE(bus.start());
  CHECK(bus.state() == BusState::Operational);
  std::array<AxisIo, 2> io{};
  REQUIRE(bus.submit({7, 1, reg::kSystemCyclePrescaler, 2, false, 0}));
  REQUIRE(bus.submit({8, 5, reg::kEnDatMode, 1, false, 0}));  // no axis 5
  const auto r = bus.exchange(io, 0, 0);
  CHECK(r.bus_up);
  CHECK(r.net_time.valid);
  RegisterResult res;
  REQUIRE(bus.poll(res));
  CHECK(res.tag == 7);
  CHECK_FALSE(res.error);
  CHECK(res.value == 4);
  REQUIRE(bus.poll(res));
  CHECK(res.tag == 8);
  CHECK(res.error);
  CHECK_FALSE(bus.poll(res));
  CHECK(io[0].inputs_fresh);
}

TEST_CASE("function model 254: MTUs power up unset and take 3..5 only, identification after Rescan",
          "[sim][fm254]") {
  Ds1928Module m(FunctionModel::BusController, constant(100));
  uint32_t v = 99;
  REQUIRE_FALSE(m.read_register(reg::kOutputMtu, 1, v));
  CHECK(v == 0);  // no datasheet default: the master must set it (§11.9.4.1)
  CHECK(m.write_register(reg::kOutputMtu, 1, 2) == sim::SimErrc::out_of_range);
  CHECK_FALSE(m.write_register(reg::kOutputMtu, 1, 3));
  // EnDat disabled at power-up: the encoder was not read; enabling alone reads nothing.
  CHECK_FALSE(m.endat().identification().has_value());
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  m.tick(1'000'000, 1000);
  CHECK_FALSE(m.endat().identification().has_value());
  CHECK(m.inputs().pos_cycle == 0);
  // Rescan (EnDatAck bit 1) reads the identification; positions follow.
  REQUIRE_FALSE(m.write_register(reg::kEnDatAck, 1, 0x02));
  m.tick(50'000'000, 50'000);
  CHECK(m.endat().identification().has_value());
  CHECK(m.inputs().pos_cycle != 0);
}
