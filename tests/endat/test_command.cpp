// Request bytes and reply decoding of the ten module commands against X20DS1928.md §7.
#include <catch2/catch.hpp>
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "endat/command.hpp"

using namespace ds1928::endat;
using Bytes = std::vector<uint8_t>;

namespace {

Bytes encode(const Request& r, CommandSet set = CommandSet::EnDat22) {
  auto m = encode_request(r, set);
  REQUIRE(m.has_value());
  return Bytes(m->span().begin(), m->span().end());
}

}  // namespace

TEST_CASE("Request bytes follow the datasheet table", "[endat][command]") {
  // | cmd | request bytes |
  CHECK(encode(Request::reset()) == Bytes{0x00});
  CHECK(encode(Request::acknowledge()) == Bytes{0x01});
  CHECK(encode(Request::read(0xA9, 0x03)) == Bytes{0x04, 0xA9, 0x03});
  CHECK(encode(Request::write(0xAB, 0x07, 0xBEEF)) == Bytes{0x05, 0xAB, 0x07, 0xEF, 0xBE});
  CHECK(encode(Request::read_block(0xB1, 0x02, 0x11)) == Bytes{0x06, 0xB1, 0x02, 0x11});
  CHECK(encode(Request::write_block(0xB1, 0x02, 0x11, 0x0102)) ==
        Bytes{0x07, 0xB1, 0x02, 0x11, 0x02, 0x01});
  CHECK(encode(Request::read_info(1, 0x4C)) == Bytes{0x08, 0x4C});
  CHECK(encode(Request::read_info(2, 0x4C)) == Bytes{0x09, 0x4C});
  CHECK(encode(Request::read_info(3, 0x51)) == Bytes{0x0A, 0x51});
  CHECK(encode(Request::read_info(4, 0x5B)) == Bytes{0x0B, 0x5B});
  // Fields a command does not carry are not sent.
  Request r = Request::reset();
  r.mrs = 0xA1;
  r.value = 0x1234;
  CHECK(encode(r) == Bytes{0x00});
}

TEST_CASE("Request and reply sizes per command", "[endat][command]") {
  struct Row {
    Command c;
    std::size_t req, rep;
    bool v22;
  };
  const Row rows[] = {{Command::Reset, 1, 1, false},
                      {Command::AcknowledgeErrors, 1, 1, false},
                      {Command::ReadParameter, 3, 5, false},
                      {Command::WriteParameter, 5, 3, false},
                      {Command::ReadBlockParameter, 4, 6, true},
                      {Command::WriteBlockParameter, 6, 4, true},
                      {Command::ReadInfoWord1, 2, 4, true},
                      {Command::ReadInfoWord2, 2, 6, true},
                      {Command::ReadInfoWord3, 2, 8, true},
                      {Command::ReadInfoWord4, 2, 10, true}};
  for (const auto& row : rows) {
    CHECK(request_size(row.c) == row.req);
    CHECK(reply_size(row.c) == row.rep);
    CHECK(requires_endat22(row.c) == row.v22);
  }
  for (unsigned b = 0; b < 256; ++b) {
    const bool known = b == 0 || b == 1 || (b >= 4 && b <= 0x0B);
    CHECK(command_from_byte(static_cast<uint8_t>(b)).has_value() == known);
  }
}

TEST_CASE("Replies decode per the datasheet table", "[endat][command]") {
  SECTION("reset and acknowledge echo the command byte") {
    auto r = decode_reply(Request::reset(), Bytes{0x00});
    REQUIRE(r);
    CHECK(r->word_count == 0);
    CHECK(decode_reply(Request::acknowledge(), Bytes{0x01}).has_value());
  }
  SECTION("read parameter: 04 MRS P VL VH") {
    auto r = decode_reply(Request::read(0xA9, 3), Bytes{0x04, 0xA9, 0x03, 0x34, 0x12});
    REQUIRE(r);
    CHECK(r->value() == 0x1234);
    CHECK(r->echo.mrs == 0xA9);
    CHECK(r->echo.parameter == 3);
  }
  SECTION("write parameter: 05 MRS P") {
    auto r = decode_reply(Request::write(0xA9, 3, 0x55AA), Bytes{0x05, 0xA9, 0x03});
    REQUIRE(r);
    CHECK(r->word_count == 0);
    CHECK(r->echo.value == 0x55AA);
  }
  SECTION("read block parameter: 06 MRS B P VL VH") {
    auto r =
        decode_reply(Request::read_block(0xB1, 2, 9), Bytes{0x06, 0xB1, 0x02, 0x09, 0xCD, 0xAB});
    REQUIRE(r);
    CHECK(r->value() == 0xABCD);
    CHECK(r->echo.block == 2);
  }
  SECTION("write block parameter: 07 MRS B P") {
    CHECK(decode_reply(Request::write_block(0xB1, 2, 9, 7), Bytes{0x07, 0xB1, 0x02, 0x09}));
  }
  SECTION("info words: the last word is the one asked for") {
    auto w1 = decode_reply(Request::read_info(1, 0x4C), Bytes{0x08, 0x4C, 0x01, 0x00});
    REQUIRE(w1);
    CHECK(w1->value() == 0x0001);
    auto w4 =
        decode_reply(Request::read_info(4, 0x4C), Bytes{0x0B, 0x4C, 1, 0, 2, 0, 3, 0, 0x04, 0x0E});
    REQUIRE(w4);
    CHECK(w4->word_count == 4);
    CHECK(w4->words[0] == 1);
    CHECK(w4->words[1] == 2);
    CHECK(w4->words[2] == 3);
    CHECK(w4->value() == 0x0E04);
    auto w2 = decode_reply(Request::read_info(2, 0x51), Bytes{0x09, 0x51, 9, 0, 0x10, 0x20});
    REQUIRE(w2);
    CHECK(w2->value() == 0x2010);
    auto w3 = decode_reply(Request::read_info(3, 0x51), Bytes{0x0A, 0x51, 0, 0, 0, 0, 0xFF, 0x7F});
    REQUIRE(w3);
    CHECK(w3->value() == 0x7FFF);
  }
}

TEST_CASE("Every reply error is named", "[endat][command]") {
  const auto read = Request::read(0xA9, 3);
  CHECK(decode_reply(read, Bytes{}).error() == Errc::truncated_reply);
  CHECK(decode_reply(read, Bytes{0x04, 0xA9, 0x03, 0x34}).error() == Errc::truncated_reply);
  CHECK(decode_reply(read, Bytes{0x04, 0xA9, 0x03, 0x34, 0x12, 0x00}).error() ==
        Errc::oversized_reply);
  CHECK(decode_reply(read, Bytes{0x05, 0xA9, 0x03, 0x34, 0x12}).error() ==
        Errc::command_echo_mismatch);
  CHECK(decode_reply(read, Bytes{0x04, 0xAB, 0x03, 0x34, 0x12}).error() == Errc::mrs_echo_mismatch);
  CHECK(decode_reply(read, Bytes{0x04, 0xA9, 0x04, 0x34, 0x12}).error() ==
        Errc::parameter_echo_mismatch);
  CHECK(
      decode_reply(Request::read_block(0xB1, 2, 9), Bytes{0x06, 0xB1, 0x03, 0x09, 0, 0}).error() ==
      Errc::block_echo_mismatch);
  CHECK(decode_reply(Request::read_info(2, 0x4C), Bytes{0x09, 0x4D, 0, 0, 0, 0}).error() ==
        Errc::mrs_echo_mismatch);

  SECTION("echo errors share a condition") {
    for (auto e : {Errc::command_echo_mismatch, Errc::mrs_echo_mismatch, Errc::block_echo_mismatch,
                   Errc::parameter_echo_mismatch}) {
      CHECK(make_error_code(e) == Condition::echo_mismatch);
      CHECK(make_error_code(e) == Condition::malformed_reply);
    }
    CHECK(make_error_code(Errc::truncated_reply) != Condition::echo_mismatch);
    CHECK(make_error_code(Errc::truncated_reply) == Condition::malformed_reply);
  }

  SECTION("failure replies") {
    CHECK(decode_reply(read, Bytes{0x84, 1}).error() == Errc::module_crc_failure);
    CHECK(decode_reply(read, Bytes{0x84, 2}).error() == Errc::module_no_response);
    CHECK(decode_reply(read, Bytes{0x84, 3}).error() == Errc::module_not_supported);
    CHECK(decode_reply(read, Bytes{0x84, 4}).error() == Errc::module_malformed_request);
    CHECK(decode_reply(read, Bytes{0x84, 5}).error() == Errc::module_wire_echo_mismatch);
    CHECK(decode_reply(read, Bytes{0x84, 0x77}).error() == Errc::module_unknown_failure);
    CHECK(decode_reply(read, Bytes{0x84}).error() == Errc::truncated_failure_reply);
    CHECK(decode_reply(read, Bytes{0x84, 1, 0}).error() == Errc::oversized_failure_reply);
    CHECK(decode_reply(read, Bytes{0x84, 1}).error() == Condition::module_failure);
    // A failure marker of another command is an echo mismatch, not a failure of this one.
    CHECK(decode_reply(read, Bytes{0x85, 1}).error() == Errc::command_echo_mismatch);
    auto enc = encode_failure_reply(0x05, FailureReason::NoResponse);
    CHECK(Bytes(enc.span().begin(), enc.span().end()) == Bytes{0x85, 0x02});
    CHECK(decode_reply(Request::reset(), Bytes{0x80, 1}).error() == Errc::module_crc_failure);
  }
}

TEST_CASE("EnDat 2.2 commands are refused for an EnDat 2.1 encoder", "[endat][command]") {
  for (Command c : kAllCommands) {
    Request r{c, 0xA9, 0, 0, 0};
    if (is_info_read(c)) r.mrs = 0x4C;
    const auto on21 = encode_request(r, CommandSet::EnDat21);
    const auto on22 = encode_request(r, CommandSet::EnDat22);
    CHECK(on22.has_value());
    if (requires_endat22(c)) {
      CHECK(on21.error() == Errc::requires_endat22);
      CHECK(on21.error() == Condition::bad_request);
      CHECK(on21.error().message().find("EnDat 2.2") != std::string::npos);
    } else {
      CHECK(on21.has_value());
    }
  }
}

TEST_CASE("Requests with an MRS outside the command's range are refused", "[endat][command]") {
  CHECK(encode_request(Request::read(0x4C, 0), CommandSet::EnDat22).error() == Errc::invalid_mrs);
  CHECK(encode_request(Request::read(0xC1, 0), CommandSet::EnDat22).error() == Errc::invalid_mrs);
  CHECK(encode_request(Request::read_info(1, 0xA1), CommandSet::EnDat22).error() ==
        Errc::invalid_mrs);
  CHECK(encode_request(Request::read_info(1, 0x60), CommandSet::EnDat22).error() ==
        Errc::invalid_mrs);
  CHECK(encode_request(Request::read(0xBF, 0), CommandSet::EnDat22).has_value());
  CHECK(encode_request(Request::read_info(1, 0x5F), CommandSet::EnDat22).has_value());
  Request bogus{static_cast<Command>(0x02)};
  CHECK(encode_request(bogus, CommandSet::EnDat22).error() == Errc::unknown_command);
}

TEST_CASE("Module side: strict request decoding", "[endat][command]") {
  CHECK(decode_request(Bytes{}).error() == Errc::truncated_request);
  CHECK(decode_request(Bytes{0x02}).error() == Errc::unknown_command);
  CHECK(decode_request(Bytes{0x03}).error() == Errc::unknown_command);
  CHECK(decode_request(Bytes{0x0C}).error() == Errc::unknown_command);
  CHECK(decode_request(Bytes{0x04, 0xA9}).error() == Errc::truncated_request);
  CHECK(decode_request(Bytes{0x00, 0x00}).error() == Errc::oversized_request);
  auto w = decode_request(Bytes{0x07, 0xB1, 2, 9, 0x34, 0x12});
  REQUIRE(w);
  CHECK(w->command == Command::WriteBlockParameter);
  CHECK(w->mrs == 0xB1);
  CHECK(w->block == 2);
  CHECK(w->parameter == 9);
  CHECK(w->value == 0x1234);
}

TEST_CASE("Module side: reply encoding matches the table", "[endat][command]") {
  const uint16_t words[] = {0x1111, 0x2222, 0x3333, 0x4444};
  auto bytes = [](const ReplyMessage& m) { return Bytes(m.span().begin(), m.span().end()); };
  CHECK(bytes(encode_reply(Request::reset())) == Bytes{0x00});
  CHECK(bytes(encode_reply(Request::read(0xA1, 13), words)) == Bytes{0x04, 0xA1, 13, 0x11, 0x11});
  CHECK(bytes(encode_reply(Request::write(0xA9, 1, 5))) == Bytes{0x05, 0xA9, 1});
  CHECK(bytes(encode_reply(Request::read_block(0xB1, 3, 1), words)) ==
        Bytes{0x06, 0xB1, 3, 1, 0x11, 0x11});
  CHECK(bytes(encode_reply(Request::write_block(0xB1, 3, 1, 9))) == Bytes{0x07, 0xB1, 3, 1});
  CHECK(bytes(encode_reply(Request::read_info(3, 0x4C), words)) ==
        Bytes{0x0A, 0x4C, 0x11, 0x11, 0x22, 0x22, 0x33, 0x33});
}

TEST_CASE("Write verification by read-back", "[endat][command]") {
  CHECK_FALSE(check_readback(0x1234, 0x1234));
  CHECK(check_readback(0x1234, 0x0000) == Errc::write_not_applied);
}

TEST_CASE("Every error code and condition has its own message", "[endat][command]") {
  std::set<std::string> seen;
  for (int e = static_cast<int>(Errc::truncated_reply);
       e <= static_cast<int>(Errc::number_out_of_range); ++e) {
    const std::string m = make_error_code(static_cast<Errc>(e)).message();
    CHECK(m.find("unknown endat error") == std::string::npos);
    CHECK(seen.insert(m).second);
  }
  CHECK(make_error_code(static_cast<Errc>(999)).message() == "unknown endat error 999");
  CHECK(std::string(error_category().name()) == "endat");
  for (int c = 1; c <= 4; ++c) {
    CHECK(make_error_condition(static_cast<Condition>(c)).message().find("unknown") ==
          std::string::npos);
  }
}
