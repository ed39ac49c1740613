// The simulated X20DS1928 against the datasheet's register behaviour (X20DS1928.md §2–§5).
#include <catch2/catch.hpp>

#include "endat/names.hpp"
#include "module_ticks.hpp"
#include "sim/ds1928_module.hpp"
#include "sim/sim_error.hpp"
#include "sim/simulated_bus.hpp"
#include "x20ds1928/info_channels.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using sim::Ds1928Module;

namespace {
using sim::test::constant;
using sim::test::kUs;
using sim::test::step;

// Runs the module for `ticks` system ticks of 100 µs, one bus cycle per tick.
int count_pos_cycle_changes(Ds1928Module& m, int ticks, int64_t& t) {
  int changes = 0;
  int8_t last = m.inputs().pos_cycle;
  for (int i = 0; i < ticks; ++i) {
    step(m, t);
    if (m.inputs().pos_cycle != last) ++changes;
    last = m.inputs().pos_cycle;
  }
  return changes;
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
  std::vector<AxisConfig> axes(2);
  axes[1].module.prescaler = 4;
  sim::SimulatedBus bus(axes, SimulatedBusConfig{});
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

TEST_CASE("EnDatAck reads back its bits until the module ran them (Rescan, acknowledge)",
          "[sim][endat_ack]") {
  Ds1928Module m(FunctionModel::BusController, constant(100));
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  int64_t t = 1'000'000;
  m.tick(t, static_cast<uint64_t>(t / kUs));
  uint32_t v = 0;
  REQUIRE_FALSE(m.read_register(reg::kEnDatAck, 1, v));
  CHECK(v == 0);
  REQUIRE_FALSE(m.write_register(reg::kEnDatAck, 1, 0x02));
  // Reading the identification takes dozens of EnDat transactions on the wire: the bit stays
  // set for as long.
  REQUIRE_FALSE(m.read_register(reg::kEnDatAck, 1, v));
  CHECK(v == 0x02);
  int reads = 0;
  while (v != 0 && reads < 100000) {
    step(m, t);
    REQUIRE_FALSE(m.read_register(reg::kEnDatAck, 1, v));
    ++reads;
  }
  CHECK(v == 0);
  CHECK(reads > 1);
  CHECK(m.endat().identification().has_value());
  uint32_t word = 0;
  REQUIRE_FALSE(m.read_register(reg::kParamManuf0 + 13, 2, word));
  CHECK((word & 0x3F) == m.endat().identification()->position_bits);  // clock pulses
  // Acknowledge (bit 0): set until the acknowledge ran on the wire.
  REQUIRE_FALSE(m.write_register(reg::kEnDatAck, 1, 0x01));
  REQUIRE_FALSE(m.read_register(reg::kEnDatAck, 1, v));
  CHECK((v & 0x01) != 0);
  for (int i = 0; i < 1000 && v != 0; ++i) {
    step(m, t);
    REQUIRE_FALSE(m.read_register(reg::kEnDatAck, 1, v));
  }
  CHECK(v == 0);
}

namespace {
// Runs a module for `seconds` with EnDatMode `mode` and returns PositionHW:PositionLW, and whether
// any position had one of the low 3 bits set.
std::pair<uint64_t, bool> run_format(uint8_t mode, double velocity, double seconds) {
  Ds1928Module m(FunctionModel::Standard, constant(velocity));
  REQUIRE_FALSE(m.write_register(reg::kSystemCyclePrescaler, 2, 2));
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, mode));
  int64_t t = 0;
  bool low_bits = false;
  for (int i = 0; i < static_cast<int>(seconds * 10000); ++i) {
    t += 100 * kUs;
    m.tick(t, static_cast<uint64_t>(t / kUs));
    low_bits |= (m.inputs().position_lw & 7u) != 0;
  }
  const auto in = m.inputs();
  return {(uint64_t{in.position_hw} << 32) | in.position_lw, low_bits};
}
}  // namespace

TEST_CASE("each EnDatMode position format: sin/cos 48.16, or the EnDat position in steps",
          "[sim][format]") {
  using namespace endat_mode;
  // The default simulated encoder: 2^25 steps per revolution, 2048 signal periods, 37 bits
  // (12 multiturn): 16384 steps per sine period.
  const auto encoder = sim::default_encoder_description();
  const double steps_per_period =
      static_cast<double>(encoder.steps_per_revolution) / encoder.signal_periods;
  for (const uint8_t clock : {uint8_t{0}, kFastClockOff}) {  // timing only: same values
    INFO("fast clock off: " << (clock != 0));
    const auto [fixed, fixed_low] = run_format(kEnable | clock, 1000.0, 0.5);
    CHECK_FALSE(fixed_low);
    CHECK(static_cast<double>(fixed) / 65536.0 == Approx(500.0).margin(0.25));
    const auto [steps, steps_low] = run_format(kEnable | kSinCosUnused | clock, 1000.0, 0.5);
    // The position in measuring steps: every bit counts, the low ones move too.
    CHECK(steps_low);
    CHECK(static_cast<double>(steps) ==
          Approx(500.0 * steps_per_period).margin(0.25 * steps_per_period));
    CHECK(steps < (uint64_t{1} << 37));
    // Backwards from zero: unsigned = the encoder's 37-bit two's complement; signed =
    // sign-extended to 64 bits.
    const auto [uns, u_low] = run_format(kEnable | kSinCosUnused | clock, -10.0, 0.5);
    CHECK(uns < (uint64_t{1} << 37));
    CHECK(uns > (uint64_t{1} << 36));
    const auto [sgn, s_low] = run_format(kEnable | kSinCosUnused | kSigned | clock, -10.0, 0.5);
    CHECK(static_cast<double>(static_cast<int64_t>(sgn)) ==
          Approx(-5.0 * steps_per_period).margin(0.25 * steps_per_period));
    CHECK((sgn & ((uint64_t{1} << 37) - 1)) == uns);
    // Signed sin/cos: two's complement of the fixed point.
    const auto [sfix, sf_low] = run_format(kEnable | kSigned | clock, -10.0, 0.5);
    CHECK(static_cast<double>(static_cast<int64_t>(sfix)) / 65536.0 == Approx(-5.0).margin(0.25));
  }
}

TEST_CASE(
    "sin/cos amplitude outside the Vss window: VssCheckError, the last good position held "
    "until SinCosQuitTime after the fault",
    "[sim][faults]") {
  Ds1928Module m(FunctionModel::Standard, constant(1000.0));
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  REQUIRE_FALSE(m.write_register(reg::kSinCosQuitTime, 4, 50'000));  // 50 ms
  int64_t t = 0;
  for (int i = 0; i < 100; ++i) step(m, t);
  CHECK(m.inputs().error_info == 0);
  m.set_vss_mv(500);  // below SinCosVssMin (800)
  for (int i = 0; i < 10; ++i) step(m, t);
  const ModuleInputs held = m.inputs();
  CHECK((held.error_info & error_info::kVssCheckError) != 0);
  for (int i = 0; i < 100; ++i) step(m, t);  // 10 ms: held, PosCycle stands
  CHECK(m.inputs().pos_cycle == held.pos_cycle);
  CHECK(m.inputs().position_lw == held.position_lw);
  m.set_vss_mv(1300);  // above SinCosVssMax (1200): still a fault
  for (int i = 0; i < 20; ++i) step(m, t);
  CHECK(m.inputs().pos_cycle == held.pos_cycle);
  m.set_vss_mv(1000);  // good again: ignored for QuitTime (50 ms = 500 ticks)
  for (int i = 0; i < 450; ++i) step(m, t);
  CHECK(m.inputs().pos_cycle == held.pos_cycle);
  CHECK(m.inputs().position_lw == held.position_lw);
  for (int i = 0; i < 100; ++i) step(m, t);
  CHECK(m.inputs().pos_cycle != held.pos_cycle);
  CHECK(m.inputs().position_lw != held.position_lw);
  // Latched until acknowledged (AckErrorInfo bit 2, a rising edge).
  CHECK((m.inputs().error_info & error_info::kVssCheckError) != 0);
  ModuleOutputs out;
  out.ack_error_info = error_info::kVssCheckError;
  m.apply_outputs(out);
  step(m, t);
  CHECK((m.inputs().error_info & error_info::kVssCheckError) == 0);
  // Detection disabled (ErrorEnable bit 2 clear): the amplitude is not judged.
  REQUIRE_FALSE(m.write_register(reg::kErrorEnable, 1, 0xFB));
  m.set_vss_mv(100);
  const int8_t before = m.inputs().pos_cycle;
  for (int i = 0; i < 20; ++i) step(m, t);
  CHECK(m.inputs().pos_cycle != before);
  CHECK((m.inputs().error_info & error_info::kVssCheckError) == 0);
}

TEST_CASE("the four EnDatInfo channels answer the encoder's additional information (§11.8.3)",
          "[sim][info]") {
  for (const FunctionModel fm : {FunctionModel::Standard, FunctionModel::BusController}) {
    Ds1928Module m(fm, constant(100));
    ModuleSettings s;
    s.input_mtu = s.output_mtu = 5;  // within function model 254's range too
    s.info_cmd[0] = encode_info_command(named_info_request(*find_named_info("temperature1")));
    s.info_cmd[1] = encode_info_command(named_info_request(*find_named_info("position2_word1")));
    // Channel 3 off; channel 4 an EnDat 2.1 read of a manufacturer word (MRS 0xA1, word 13).
    s.info_cmd[3] = encode_info_command({info_command::kReadParameter, 0xA1, 13, std::nullopt});
    REQUIRE_FALSE(configure_module(m, s));
    uint32_t v = 0;
    REQUIRE_FALSE(m.read_register(reg::kEnDatInfoCmd01 + 8, 4, v));
    CHECK(v == s.info_cmd[1]);
    m.endat().encoder().set_temperature_c(55.0);
    m.endat().encoder().set_position2(0x1234'ABCDu);
    int64_t t = 1'000'000;
    for (int i = 0; i < 20; ++i) step(m, t);
    const ModuleInputs in = m.inputs();
    CHECK(in.info_ok == 0x0B);  // 1, 2 and 4 valid; 3 off
    CHECK(in.info[0] == endat::temperature_raw(55.0));
    CHECK(in.info[1] == 0xABCD);
    CHECK(in.info[3] == *m.endat().encoder().word(0xA1, 0, 13));
    CHECK(in.info[2] == 0);
    // The registers read the same words.
    REQUIRE_FALSE(m.read_register(reg::kEnDatInfoOk, 1, v));
    CHECK(v == 0x0B);
    REQUIRE_FALSE(m.read_register(reg::kEnDatInfo01, 2, v));
    CHECK(v == endat::temperature_raw(55.0));
    REQUIRE_FALSE(m.read_register(reg::kEnDatInfo01 + 16, 2, v));
    CHECK(v == 0xABCD);
    // The value follows the encoder; a new request is invalid until served.
    m.endat().encoder().set_temperature_c(-10.0);
    REQUIRE_FALSE(m.write_register(reg::kEnDatInfoCmd01 + 16, 4,
                                   encode_info_command({0x08, 0x4D, 0, std::nullopt})));
    CHECK((m.inputs().info_ok & 0x04) == 0);
    for (int i = 0; i < 20; ++i) step(m, t);
    CHECK(m.inputs().info[0] == endat::temperature_raw(-10.0));
    CHECK(m.inputs().info[2] == endat::temperature_raw(38.0));  // temperature 2's default
    CHECK(m.inputs().info_ok == 0x0F);
    CHECK(m.write_register(reg::kEnDatInfoCmd01, 2, 0));  // UDINT: a 2-byte write is refused
  }
}
