// The register catalogue is the one source of register facts: the codecs' offsets, the start-up
// writes, the simulated module and docs/registers.md must agree with it.
#include "core/register_catalogue.hpp"

#include <catch2/catch.hpp>
#include <fstream>
#include <set>
#include <sstream>

#include "powerlink/process_image.hpp"
#include "sim/ds1928_module.hpp"

using namespace ds1928;

namespace {
const RegisterInfo& entry(uint16_t reg) {
  const RegisterInfo* r = find_register(reg);
  REQUIRE(r != nullptr);
  return *r;
}
}  // namespace

TEST_CASE("Catalogue: cyclic offsets of the codecs are the catalogue's", "[registers]") {
  CHECK(entry(4180).fm0_offset == int(fm0::kPositionHw));
  CHECK(entry(4188).fm0_offset == int(fm0::kPositionLw));
  CHECK(entry(4172).fm0_offset == int(fm0::kPosTime));
  CHECK(entry(4163).fm0_offset == int(fm0::kPosCycle));
  CHECK(entry(683).fm0_offset == int(fm0::kSdcLifeCount));
  CHECK(entry(261).fm0_offset == int(fm0::kErrorInfo));
  CHECK(entry(4672).fm0_offset == int(fm0::kInputSequence));
  CHECK(entry(4673).fm0_offset == int(fm0::kRxBytes));
  CHECK(entry(4704).fm0_offset == int(fm0::kOutputSequence));
  CHECK(entry(4705).fm0_offset == int(fm0::kTxBytes));
  CHECK(entry(325).fm0_after_tx_bytes);
  CHECK(fm0::kRxBytes == powerlink::kPresModuleFixedSize);

  // Datasheet §11.3.2 (FM254): PositionHW 0–3, PositionLW 4–7, InputSequence 8, RxByte1–5 9–13,
  // ErrorInfo 14, PosCycle 15; OutputSequence 0, TxByte1–5 1–5, AckErrorInfo 6.
  CHECK(entry(4180).can_offset == 0);
  CHECK(entry(4188).can_offset == 4);
  CHECK(entry(4672).can_offset == 8);
  CHECK(entry(4673).can_offset == 9);
  CHECK(entry(4673).members(FunctionModel::BusController) == 5);
  CHECK(entry(4673).members(FunctionModel::Standard) == 15);
  CHECK(entry(261).can_offset == 14);
  CHECK(entry(4163).can_offset == 15);
  CHECK(entry(4704).can_offset == 0);
  CHECK(entry(4705).can_offset == 1);
  CHECK(entry(325).can_offset == 6);
  CHECK(entry(4180).can_offset == int(fm254::kPositionHw));
  CHECK(entry(4188).can_offset == int(fm254::kPositionLw));
  CHECK(entry(4672).can_offset == int(fm254::kInputSequence));
  CHECK(entry(4673).can_offset == int(fm254::kRxBytes));
  CHECK(entry(261).can_offset == int(fm254::kErrorInfo));
  CHECK(entry(4163).can_offset == int(fm254::kPosCycle));
  CHECK(entry(325).can_offset == int(fm254::kAckErrorInfo));
  // No PosTime and no SDCLifeCount under function model 254.
  CHECK((entry(4172).models & kFm254) == 0);
  CHECK((entry(683).models & kFm254) == 0);
}

TEST_CASE("Catalogue: every cyclic byte of a CAN object belongs to exactly one register",
          "[registers]") {
  std::array<int, 16> in{};
  std::array<int, 8> out{};
  for (const RegisterInfo& r : register_catalogue()) {
    if (r.can_offset == kNoOffset) continue;
    const int bytes = r.members(FunctionModel::BusController) * r.size;
    for (int b = 0; b < bytes; ++b) {
      if (r.direction == RegisterDirection::In)
        ++in.at(static_cast<std::size_t>(r.can_offset + b));
      else
        ++out.at(static_cast<std::size_t>(r.can_offset + b));
    }
  }
  for (int n : in) CHECK(n == 1);
  for (std::size_t b = 0; b < 7; ++b) CHECK(out[b] == 1);
  CHECK(out[7] == 0);  // unused
}

TEST_CASE("Catalogue: lookups by member and sizes", "[registers]") {
  CHECK(register_size(4352) == 2);
  CHECK(register_size(4399) == 2);
  CHECK(register_size(4415) == 2);
  CHECK(register_size(4479) == 2);
  CHECK(register_size(4868 + 8 * 3) == 4);
  CHECK_FALSE(register_size(4868 + 4).has_value());  // between two EnDatInfoCmd members
  CHECK(register_size(4994 + 16) == 2);
  CHECK(register_size(1044) == 4);
  CHECK_FALSE(register_size(1).has_value());
  CHECK(entry(4687).number == 4673);  // RxByte15
  CHECK((find_register(4688) == nullptr || find_register(4688)->number != 4673));
}

TEST_CASE("Catalogue: start-up writes cover every configuration register, EnDatMode last",
          "[registers]") {
  ModuleSettings s;
  s.output_mtu = 5;
  s.input_mtu = 4;
  s.prescaler = 8;
  const auto writes = startup_writes(s);
  std::set<uint16_t> seen;
  for (const RegisterWrite& w : writes) {
    INFO("register " << w.reg);
    REQUIRE(w.reg != 0);
    CHECK(seen.insert(w.reg).second);
    CHECK(register_size(w.reg) == w.size);
    CHECK(entry(w.reg).direction == RegisterDirection::Config);
  }
  CHECK(writes.back().reg == reg::kEnDatMode);
  CHECK(writes.back().value == s.endat_mode());
  auto value_of = [&](uint16_t r) {
    for (const RegisterWrite& w : writes)
      if (w.reg == r) return w.value;
    FAIL("register " << r << " not written");
    return 0u;
  };
  CHECK(value_of(reg::kOutputMtu) == 5);
  CHECK(value_of(reg::kInputMtu) == 4);
  CHECK(value_of(reg::kSystemCyclePrescaler) == 8);
  CHECK(value_of(reg::kSinCosEnable) == 1);
}

TEST_CASE("Catalogue: the simulated module powers up with the catalogue's defaults and sizes",
          "[registers]") {
  for (FunctionModel fm : {FunctionModel::Standard, FunctionModel::BusController}) {
    sim::Ds1928Module m(fm, SimAxisConfig{});
    for (const RegisterInfo& r : register_catalogue()) {
      if (r.direction != RegisterDirection::Config || !r.default_value) continue;
      INFO(r.name);
      uint32_t v = 0xDEAD;
      REQUIRE_FALSE(m.read_register(r.number, r.size, v));
      CHECK(v == *r.default_value);
      if (r.size != 4) CHECK(m.read_register(r.number, 4, v));  // wrong size refused
    }
  }
}

TEST_CASE("Catalogue: docs/registers.md holds the catalogue's table", "[registers][docs]") {
  std::ifstream f(DS1928_SOURCE_DIR "/docs/registers.md");
  REQUIRE(f.good());
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string doc = ss.str();
  const std::string begin = "<!-- register-catalogue:begin -->\n";
  const std::string end = "<!-- register-catalogue:end -->";
  const auto a = doc.find(begin);
  const auto b = doc.find(end);
  REQUIRE(a != std::string::npos);
  REQUIRE(b != std::string::npos);
  const std::string table = doc.substr(a + begin.size(), b - a - begin.size());
  INFO("docs/registers.md must contain between the markers exactly:\n" << catalogue_markdown());
  CHECK(table == catalogue_markdown());
}
