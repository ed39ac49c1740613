// The simulated X20DS1928 failing as the datasheet describes (X20DS1928.md §3, §5): the encoder
// supply, the encoder's own error and warning words, and the faults a configuration schedules.
#include <catch2/catch.hpp>

#include "module_ticks.hpp"
#include "sim/ds1928_module.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using sim::Ds1928Module;
using sim::test::constant;

namespace {
// `n` system ticks of 100 µs.
void run(Ds1928Module& m, int64_t& t, int n) {
  for (int i = 0; i < n; ++i) sim::test::step(m, t);
}
uint16_t read(const Ds1928Module& m, uint16_t reg) {
  uint32_t v = 0;
  REQUIRE_FALSE(m.read_register(reg, 2, v));
  return static_cast<uint16_t>(v);
}
void ack_error_info(Ds1928Module& m, uint8_t bits) {
  ModuleOutputs out;
  m.apply_outputs(out);
  out.ack_error_info = bits;
  m.apply_outputs(out);
}
}  // namespace

TEST_CASE(
    "encoder supply below 5 V -5 %: EncoderSupplyError and no position until it is back, "
    "latched until acknowledged",
    "[sim][faults]") {
  Ds1928Module m(FunctionModel::Standard, constant(1000.0));
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  int64_t t = 0;
  run(m, t, 100);
  REQUIRE(m.inputs().error_info == 0);
  m.set_supply_mv(4760);  // within the tolerance
  run(m, t, 20);
  CHECK(m.inputs().error_info == 0);
  m.set_supply_mv(4740);
  run(m, t, 2);  // one EnDat cycle (prescaler 2)
  const ModuleInputs low = m.inputs();
  CHECK(low.error_info == error_info::kEncoderSupplyError);
  run(m, t, 100);
  CHECK(m.inputs().pos_cycle == low.pos_cycle);
  CHECK(m.inputs().position_lw == low.position_lw);
  // An acknowledge while the supply is still low: the next EnDat cycle sets the bit again.
  ack_error_info(m, error_info::kEncoderSupplyError);
  run(m, t, 2);
  CHECK(m.inputs().error_info == error_info::kEncoderSupplyError);
  m.set_supply_mv(5000);
  run(m, t, 4);
  CHECK(m.inputs().pos_cycle != low.pos_cycle);
  CHECK(m.inputs().error_info == error_info::kEncoderSupplyError);  // latched
  ack_error_info(m, 0);
  ack_error_info(m, error_info::kEncoderSupplyError);
  CHECK(m.inputs().error_info == 0);
  // Detection off (ErrorEnable bit 0 clear): no bit, but still no position from the encoder.
  REQUIRE_FALSE(m.write_register(reg::kErrorEnable, 1, 0xFE));
  m.set_supply_mv(3000);
  run(m, t, 2);
  const int8_t off = m.inputs().pos_cycle;
  run(m, t, 50);
  CHECK(m.inputs().error_info == 0);
  CHECK(m.inputs().pos_cycle == off);
}

TEST_CASE(
    "the encoder's error and warning words move in EnDatError / EnDatWarning: set, and cleared "
    "by EnDatAck once the condition is gone",
    "[sim][faults]") {
  Ds1928Module m(FunctionModel::Standard, constant(100.0));
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  int64_t t = 0;
  run(m, t, 100);
  REQUIRE(read(m, reg::kEnDatError) == 0);
  REQUIRE(read(m, reg::kEnDatWarning) == 0);
  // Warnings (frequency collision, temperature): the module mirrors the word within its status
  // refresh (every 0.5 s); no F1, so no ErrorInfo bit and positions go on.
  m.endat().encoder().set_warning_conditions(0x0003);
  const int8_t before = m.inputs().pos_cycle;
  run(m, t, 12000);
  CHECK(read(m, reg::kEnDatWarning) == 0x0003);
  CHECK(m.inputs().error_info == 0);
  CHECK(m.inputs().pos_cycle != before);
  // Errors (lighting, battery): F1 in the position frame → EnDatPosError at once; the word follows.
  m.endat().encoder().set_error_conditions(0x0041);
  run(m, t, 4);
  CHECK((m.inputs().error_info & error_info::kEnDatPosError) != 0);
  run(m, t, 12000);
  CHECK(read(m, reg::kEnDatError) == 0x0041);
  // The conditions end; the words stay until the master clears them (EnDatAck bit 0).
  m.endat().encoder().set_error_conditions(0);
  m.endat().encoder().set_warning_conditions(0x0002);  // the temperature is still too high
  run(m, t, 12000);
  CHECK(read(m, reg::kEnDatError) == 0x0041);
  REQUIRE_FALSE(m.write_register(reg::kEnDatAck, 1, 0x01));
  run(m, t, 12000);
  CHECK(read(m, reg::kEnDatError) == 0);
  CHECK(read(m, reg::kEnDatWarning) == 0x0002);
  ack_error_info(m, error_info::kEnDatPosError);
  run(m, t, 4);
  CHECK(m.inputs().error_info == 0);
  m.endat().encoder().set_warning_conditions(0);
  REQUIRE_FALSE(m.write_register(reg::kEnDatAck, 1, 0x01));
  run(m, t, 12000);
  CHECK(read(m, reg::kEnDatWarning) == 0);
}

TEST_CASE("a configuration's faults appear faults_after_ms after power-up", "[sim][faults]") {
  SimAxisConfig c = constant(100.0);
  c.faults_after_ms = 200;
  c.inject_error_info = error_info::kEnDatRefWarning;
  c.endat_warning = 0x0001;
  c.vss_mv = 200;
  Ds1928Module m(FunctionModel::Standard, c);
  REQUIRE_FALSE(m.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  int64_t t = 0;
  run(m, t, 1900);  // 190 ms
  CHECK(m.inputs().error_info == 0);
  CHECK(read(m, reg::kEnDatWarning) == 0);
  const int8_t good = m.inputs().pos_cycle;
  run(m, t, 200);
  CHECK(m.inputs().error_info == (error_info::kEnDatRefWarning | error_info::kVssCheckError));
  const int8_t held = m.inputs().pos_cycle;
  CHECK(held != good);
  run(m, t, 12000);
  CHECK(m.inputs().pos_cycle == held);
  CHECK(read(m, reg::kEnDatWarning) == 0x0001);
  // At power-up (0): present before the first position.
  c.faults_after_ms = 0;
  c.vss_mv = 1000;
  c.supply_mv = 4000;
  Ds1928Module p(FunctionModel::Standard, c);
  REQUIRE_FALSE(p.write_register(reg::kEnDatMode, 1, endat_mode::kEnable));
  t = 0;
  run(p, t, 4);
  CHECK(p.inputs().error_info == (error_info::kEnDatRefWarning | error_info::kEncoderSupplyError));
  CHECK(p.inputs().pos_cycle == 0);
}
