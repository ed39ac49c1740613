// EnDat frames on the wire: layout, CRC coverage and error detection.
#include <catch2/catch.hpp>
#include <cstdint>
#include <random>

#include "endat/crc.hpp"
#include "endat/wire.hpp"

using namespace ds1928::endat;
using namespace ds1928::endat::wire;

TEST_CASE("Mode commands: 2.1 codes are three bits and their inverse", "[endat][wire]") {
  for (uint8_t code : {0x07, 0x0E, 0x1C, 0x23, 0x2A, 0x15, 0x31}) {
    const auto m = mode_from_bits(code);
    REQUIRE(m);
    CHECK_FALSE(is_endat22_mode(*m));
    CHECK((code >> 3) == ((~code) & 0x7));
  }
  for (uint8_t code : {0x38, 0x09, 0x1B, 0x24, 0x2D, 0x36, 0x12}) {
    const auto m = mode_from_bits(code);
    REQUIRE(m);
    CHECK(is_endat22_mode(*m));
  }
  int known = 0;
  for (unsigned c = 0; c < 64; ++c) known += mode_from_bits(static_cast<uint8_t>(c)) ? 1 : 0;
  CHECK(known == 14);
}

TEST_CASE("Master frame: mode, address, parameter MSB first", "[endat][wire]") {
  const auto f = encode_master_frame({Mode::SendParameter, 0xA5, 0x8001});
  REQUIRE(f.size() == 30);
  // 100011 | 10100101 | 1000000000000001
  const char* expect =
      "100011"
      "10100101"
      "1000000000000001";
  for (std::size_t i = 0; i < 30; ++i) CHECK(f.bit(i) == (expect[i] == '1'));
  auto back = decode_master_frame(f);
  REQUIRE(back);
  CHECK(back->mode == Mode::SendParameter);
  CHECK(back->address == 0xA5);
  CHECK(back->parameter == 0x8001);

  const auto pos = encode_master_frame({Mode::SendPosition, 0xFF, 0xFFFF});
  CHECK(pos.size() == 6);
  BitFrame bad;
  bad.push_msb_first(0x3F, 6);
  CHECK(decode_master_frame(bad).error() == Errc::invalid_mode);
  BitFrame shortf = encode_master_frame({Mode::SendParameter, 1, 2});
  shortf.truncate(20);
  CHECK(decode_master_frame(shortf).error() == Errc::frame_length);
}

TEST_CASE("Parameter reply: start bit, echo, value, CRC over both", "[endat][wire]") {
  const auto f = encode_parameter_reply({0x0D, 0x0025});
  REQUIRE(f.size() == kParameterReplyBits);
  CHECK(f.bit(0));
  std::size_t pos = 25;
  uint64_t crc = 0;
  REQUIRE(f.read_msb_first(pos, 5, crc));
  CHECK(crc == crc5_parameter(0x0D, 0x0025));
  auto r = decode_parameter_reply(f);
  REQUIRE(r);
  CHECK(r->address == 0x0D);
  CHECK(r->value == 0x0025);

  for (std::size_t bit = 1; bit < f.size(); ++bit) {
    BitFrame g = f;
    g.flip(bit);
    CHECK(decode_parameter_reply(g).error() == Errc::crc_mismatch);
  }
  BitFrame nostart = f;
  nostart.flip(0);
  CHECK(decode_parameter_reply(nostart).error() == Errc::no_response);
  CHECK(decode_parameter_reply(BitFrame{}).error() == Errc::no_response);
  BitFrame trunc = f;
  trunc.truncate(29);
  CHECK(decode_parameter_reply(trunc).error() == Errc::frame_length);
}

TEST_CASE("Position frames 2.1 and 2.2", "[endat][wire]") {
  std::mt19937_64 rng(5);
  for (int i = 0; i < 2000; ++i) {
    const unsigned n = 1 + static_cast<unsigned>(rng() % kMaxPositionBits);
    const uint64_t p = rng() & ((uint64_t{1} << n) - 1);
    const bool f1 = (rng() & 7) == 0;
    // 2.1: start, F1, position LSB first, CRC over F1 + position.
    {
      PositionReply r;
      r.f1 = f1;
      r.position = p;
      const auto f = encode_position_reply(r, CommandSet::EnDat21, n);
      REQUIRE(f.size() == 1 + 1 + n + 5);
      REQUIRE(f.bit(2) == ((p & 1) != 0));  // LSB right after F1
      Crc5 crc;
      crc.push_bit(f1);
      crc.push_lsb_first(p, n);
      std::size_t pos = 2 + n;
      uint64_t c = 0;
      REQUIRE(f.read_msb_first(pos, 5, c));
      REQUIRE(c == crc.value());
      auto d = decode_position_reply(f, {CommandSet::EnDat21, n, false, false});
      REQUIRE(d);
      REQUIRE(d->position == p);
      REQUIRE(d->f1 == f1);
    }
    // 2.2 with both additional informations.
    {
      PositionReply r;
      r.f1 = f1;
      r.f2 = !f1;
      r.position = p;
      r.ai1 = AdditionalInfo{0x0C, static_cast<uint16_t>(rng())};
      r.ai2 = AdditionalInfo{0x11, static_cast<uint16_t>(rng())};
      const auto f = encode_position_reply(r, CommandSet::EnDat22, n);
      const PositionFormat fmt{CommandSet::EnDat22, n, true, true};
      REQUIRE(f.size() == fmt.frame_bits());
      auto d = decode_position_reply(f, fmt);
      REQUIRE(d);
      REQUIRE(d->position == p);
      REQUIRE(d->ai1->data == r.ai1->data);
      REQUIRE(d->ai2->status == 0x11);
      // Any single flipped bit after the start bit is detected (CRC or F1/F2 check).
      BitFrame g = f;
      g.flip(1 + rng() % (f.size() - 1));
      REQUIRE_FALSE(decode_position_reply(g, fmt).has_value());
    }
  }
  // F2 must be the inverse of F1.
  PositionReply r;
  r.f1 = true;
  r.f2 = true;
  r.position = 5;
  const auto f = encode_position_reply(r, CommandSet::EnDat22, 8);
  CHECK(decode_position_reply(f, {CommandSet::EnDat22, 8, false, false}).error() ==
        Errc::f2_not_inverted);
  // Expecting an AI that is not there: wrong length.
  r.f2 = false;
  CHECK(decode_position_reply(encode_position_reply(r, CommandSet::EnDat22, 8),
                              {CommandSet::EnDat22, 8, true, false})
            .error() == Errc::frame_length);
}
