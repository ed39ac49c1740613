// The error-bit table (x20ds1928/error_bits.hpp) against the datasheet (§11.6.1.2, §11.6.2.1–2),
// the policy it gives the position's validity, and docs/registers.md's rendering of it.
#include "x20ds1928/error_bits.hpp"

#include <catch2/catch.hpp>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include "x20ds1928/error_bits_json.hpp"
#include "x20ds1928/module_image.hpp"

using namespace ds1928;

TEST_CASE("Error bits: every defined bit of the three registers, once", "[errors]") {
  std::set<std::string_view> names;
  std::set<std::pair<int, int>> bits;
  for (const ErrorBit& b : error_bits()) {
    CHECK(names.insert(b.name).second);
    CHECK(bits.insert({static_cast<int>(b.reg), b.bit}).second);
    CHECK(b.bit < register_width(b.reg));
    CHECK(!b.meaning.empty());
    CHECK(!b.remedy.empty());
    CHECK(find_error_bit(b.name) == &b);
    CHECK(find_error_bit(b.reg, b.bit) == &b);
  }
  // §11.6.1.2: bits 0, 2..7 (bit 1 reserved); §11.6.2.1: 0..6; §11.6.2.2: 0..4.
  CHECK(bits.size() == 7 + 7 + 5);
  CHECK(find_error_bit(ErrorRegister::ErrorInfo, 1) == nullptr);
  CHECK(find_error_bit(ErrorRegister::EnDatError, 7) == nullptr);
  CHECK(find_error_bit(ErrorRegister::EnDatWarning, 5) == nullptr);
  // The names agree with module_image.hpp's constants.
  using namespace ds1928::error_info;
  const std::pair<std::string_view, uint8_t> constants[] = {
      {"EncoderSupplyError", kEncoderSupplyError}, {"VssCheckError", kVssCheckError},
      {"PositionError", kPositionError},           {"EnDatComError", kEnDatComError},
      {"EnDatPosError", kEnDatPosError},           {"EnDatParSetError", kEnDatParSetError},
      {"EnDatRefWarning", kEnDatRefWarning}};
  for (const auto& [name, mask] : constants) {
    const ErrorBit* b = find_error_bit(name);
    REQUIRE(b != nullptr);
    CHECK(b->reg == ErrorRegister::ErrorInfo);
    CHECK((1u << b->bit) == mask);
  }
}

TEST_CASE("Error bits: the datasheet's classes", "[errors]") {
  // EnDatRefWarning is a warning (§11.6.1.1 "Warnung"); the EnDatWarning word's bits are
  // warnings (§11.6.2.2), EnDatError's faults (§11.6.2.1).
  CHECK(find_error_bit("EnDatRefWarning")->cls == ErrorClass::Warning);
  CHECK(find_error_bit("EnDatRefWarning")->default_effect() == ErrorEffect::Flag);
  CHECK(find_error_bit("VssCheckError")->default_effect() == ErrorEffect::Hold);
  CHECK(find_error_bit("EnDatComError")->default_effect() == ErrorEffect::Invalidate);
  for (const ErrorBit& b : error_bits()) {
    if (b.reg == ErrorRegister::EnDatError) CHECK(b.cls == ErrorClass::Fault);
    if (b.reg == ErrorRegister::EnDatWarning) CHECK(b.cls != ErrorClass::Fault);
  }
  // §11.6.1.1 names Rescan as the remedy for the parameter error.
  CHECK(find_error_bit("EnDatParSetError")->remedy.find("rescan") != std::string_view::npos);
  CHECK(find_error_bit("EnDatParSetError")->remedy_from_datasheet);
}

TEST_CASE("Error bits: policy by class and per-bit override", "[errors]") {
  const ErrorPolicy d = error_policy();
  const auto assess_ei = [](const ErrorPolicy& p, uint8_t ei) {
    return assess(p, ErrorWords{ei, 0, 0});
  };
  auto a = assess_ei(d, error_info::kEnDatRefWarning);
  CHECK_FALSE(a.invalidate);
  CHECK_FALSE(a.hold);
  CHECK(a.warning);
  CHECK_FALSE(a.fault);
  a = assess_ei(d, error_info::kVssCheckError);
  CHECK(a.hold);
  CHECK_FALSE(a.invalidate);
  CHECK(a.fault);
  a = assess_ei(d, error_info::kEnDatComError);
  CHECK(a.invalidate);
  CHECK(a.fault);
  CHECK_FALSE(assess_ei(d, 0x02).invalidate);  // reserved: nothing
  CHECK_FALSE(assess_ei(d, 0x02).fault);
  a = assess(d, ErrorWords{0, 0x0040, 0});  // EnDatError battery
  CHECK(a.invalidate);
  a = assess(d, ErrorWords{0, 0, 0x0002});  // EnDatWarning temperature
  CHECK_FALSE(a.invalidate);
  CHECK(a.warning);
  CHECK_FALSE(assess(d, ErrorWords{0, 0, 0x0010}).warning);  // reference point: information

  // invalidate_on: {EnDatRefWarning: true, Battery: false, VssCheckError: true}
  ErrorMasks on{}, off{};
  on[0] = error_info::kEnDatRefWarning | error_info::kVssCheckError;
  off[1] = 0x0040;
  const ErrorPolicy p = error_policy(on, off);
  CHECK(assess_ei(p, error_info::kEnDatRefWarning).invalidate);
  CHECK(assess_ei(p, error_info::kVssCheckError).hold);  // analogue: holds, as its class
  CHECK_FALSE(assess_ei(p, error_info::kVssCheckError).invalidate);
  a = assess(p, ErrorWords{0, 0x0040, 0});
  CHECK_FALSE(a.invalidate);
  CHECK(a.fault);  // still flagged as a fault
  // EnDatComError: false turns a fault into a flag.
  ErrorMasks off2{};
  off2[0] = error_info::kEnDatComError;
  CHECK_FALSE(assess_ei(error_policy({}, off2), error_info::kEnDatComError).invalidate);
}

TEST_CASE("Error bits: set bits by name, reserved ones by register", "[errors]") {
  const auto bits = set_error_bits(ErrorWords{0x12, 0x0101, 0x0000});
  REQUIRE(bits.size() == 4);
  CHECK(bits[0].label() == "ErrorInfo reserved bit 1");
  CHECK(bits[1].label() == "EnDatComError");
  CHECK(bits[2].label() == "Lighting");
  CHECK(bits[3].label() == "EnDatError reserved bit 8");
  CHECK(error_bit_list(ErrorRegister::EnDatWarning, 0) == "none");
  CHECK(error_bit_list(ErrorRegister::EnDatWarning, 0x0A) == "Temperature, BatteryCharge");
}

TEST_CASE("Error bits: the JSON list of the daemon's status and of ds1928ctl position",
          "[errors][json]") {
  const ErrorWords w{static_cast<uint8_t>(error_info::kVssCheckError | 0x02), 0x0040, 0};
  const nlohmann::json plain = error_bits_json(w);
  REQUIRE(plain.size() == 3);
  CHECK(plain[0]["name"] == "ErrorInfo reserved bit 1");
  CHECK(plain[0]["class"] == "reserved");
  CHECK_FALSE(plain[0].contains("remedy"));
  CHECK(plain[1]["name"] == "VssCheckError");
  CHECK(plain[1]["register"] == "ErrorInfo");
  CHECK(plain[1]["bit"] == 2);
  CHECK(plain[1]["class"] == "fault");
  CHECK(plain[1]["remedy"] == std::string(find_error_bit("VssCheckError")->remedy));
  CHECK_FALSE(plain[1].contains("effect"));  // no policy: no effect
  CHECK(plain[2]["register"] == "EnDatError");
  CHECK(plain[2]["name"] == "Battery");

  // With the axis' policy each bit says what it does: analogue hold, fault module_error, and a
  // fault turned into a flag by axes[].invalidate_on.
  ErrorMasks off{};
  off[1] = 0x0040;
  const nlohmann::json with = error_bits_json(w, error_policy({}, off));
  REQUIRE(with.size() == 3);
  CHECK(with[0]["effect"] == "flag");
  CHECK(with[1]["effect"] == "hold");
  CHECK(with[2]["effect"] == "flag");
  CHECK(error_bits_json(w, error_policy())[2]["effect"] == "module_error");
  CHECK(error_bits_json(ErrorWords{}).empty());
}

TEST_CASE("Error bits: docs/registers.md holds the table's rendering", "[errors][docs]") {
  std::ifstream f(DS1928_SOURCE_DIR "/docs/registers.md");
  REQUIRE(f.good());
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string doc = ss.str();
  const std::string begin = "<!-- error-bits:begin -->\n";
  const std::string end = "<!-- error-bits:end -->";
  const auto a = doc.find(begin);
  const auto b = doc.find(end);
  REQUIRE(a != std::string::npos);
  REQUIRE(b != std::string::npos);
  const std::string rendered = error_bits_markdown();
  if (std::getenv("DS1928_WRITE_REGISTERS_MD") != nullptr) {
    std::ofstream(DS1928_SOURCE_DIR "/docs/registers.md")
        << doc.substr(0, a + begin.size()) << rendered << doc.substr(b);
    return;
  }
  INFO(
      "docs/registers.md must hold between its error-bits markers exactly the rendering below; "
      "DS1928_WRITE_REGISTERS_MD=1 ctest -R x20ds1928_error_bits_test writes it:\n"
      << rendered);
  CHECK(doc.substr(a + begin.size(), b - a - begin.size()) == rendered);
}
