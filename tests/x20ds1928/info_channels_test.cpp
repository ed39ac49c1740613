// The additional-information channels' register layout (§11.8.3.1) and the named information.
#include "x20ds1928/info_channels.hpp"

#include <catch2/catch.hpp>
#include <random>
#include <set>
#include <string>
#include <utility>

#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;

TEST_CASE("EnDatInfoCmd: the datasheet's bit layout, both ways", "[info]") {
  // Unblocked: parameter on the third byte; blocked: block on the third, parameter on the fourth.
  CHECK(encode_info_command({0x04, 0xA1, 0x0D, std::nullopt}) == 0x000D'A104u);
  CHECK(encode_info_command({0x06, 0xA5, 0x03, uint8_t{1}}) == 0x0301'A506u);
  CHECK(encode_info_command({0x08, 0x4C, 0, std::nullopt}) == 0x0000'4C08u);
  CHECK(encode_info_command({}) == 0u);  // the channel off: the datasheet's default
  std::mt19937 rng(7);
  for (int i = 0; i < 10000; ++i) {
    InfoRequest r;
    r.command = static_cast<uint8_t>(rng());
    r.mrs = static_cast<uint8_t>(rng());
    r.parameter = static_cast<uint8_t>(rng());
    if (r.command == info_command::kReadBlockParameter) r.block = static_cast<uint8_t>(rng());
    CHECK(decode_info_command(encode_info_command(r)) == r);
  }
}

TEST_CASE("EnDatInfoCmd: the requests the module serves", "[info]") {
  CHECK(info_request_problem({0x04, 0xA1, 0x0D, std::nullopt}).empty());
  CHECK(info_request_problem({0x06, 0xA5, 3, uint8_t{1}}).empty());
  CHECK(info_request_problem({0x0B, 0x5B, 0, std::nullopt}).empty());
  CHECK_FALSE(info_request_problem({0x04, 0xA1, 0, uint8_t{1}}).empty());
  CHECK_FALSE(info_request_problem({0x06, 0xA5, 3, std::nullopt}).empty());
  CHECK_FALSE(info_request_problem({0x08, 0xA1, 0, std::nullopt}).empty());
  CHECK_FALSE(info_request_problem({0x08, 0x4F, 0, std::nullopt}).empty());  // stop
  CHECK_FALSE(info_request_problem({0x08, 0x4C, 1, std::nullopt}).empty());
  CHECK_FALSE(info_request_problem({0x0C, 0x4C, 0, std::nullopt}).empty());
  CHECK_FALSE(info_request_problem({}).empty());
}

TEST_CASE("Named additional information: EnDat 2.2's MRS codes, unique names", "[info]") {
  std::set<std::string> names;
  for (const NamedInfo& n : named_infos()) {
    CHECK(names.insert(std::string(n.name)).second);
    CHECK(info_request_problem(named_info_request(n)).empty());
  }
  REQUIRE(find_named_info("temperature1") != nullptr);
  CHECK(find_named_info("temperature1")->mrs == 0x4C);
  CHECK(find_named_info("temperature2")->mrs == 0x4D);
  CHECK(find_named_info("position2_word1")->mrs == 0x42);
  CHECK(find_named_info("commutation")->mrs == 0x51);
  CHECK(find_named_info("timestamp")->mrs == 0x5B);
  CHECK(find_named_info("nothing") == nullptr);
}

namespace {
template <typename T>
concept SpanOf = requires(T&& w) {
  std::forward<T>(w).span();
};
}  // namespace

TEST_CASE("InfoCommandWrites: the span of a temporary does not compile", "[info]") {
  // A range-for over info_command_writes(s).span() would read the array after its end.
  STATIC_REQUIRE(SpanOf<const InfoCommandWrites&>);
  STATIC_REQUIRE_FALSE(SpanOf<InfoCommandWrites&&>);
  ModuleSettings s;
  s.info_cmd[1] = encode_info_command({0x08, 0x4C, 0, std::nullopt});
  const InfoCommandWrites w = info_command_writes(s);
  REQUIRE(w.span().size() == 1);
  CHECK(w.span()[0].value == 0x0000'4C08u);
  CHECK(w.span()[0].reg == reg::kEnDatInfoCmd01 + 8);
}
