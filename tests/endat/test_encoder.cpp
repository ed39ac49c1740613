// Simulated encoder: YAML description, memory areas, protection, wire behaviour, faults.
#include <catch2/catch.hpp>
#include <cstdint>

#include "endat/ident.hpp"
#include "endat/wire.hpp"
#include "sim/encoder_description_yaml.hpp"
#include "sim/endat_encoder.hpp"

using namespace ds1928;
using namespace ds1928::sim;
using endat::wire::BitFrame;
using endat::wire::Mode;

namespace {

Result<endat::wire::ParameterReply> tx(EnDatEncoder& e, Mode m, uint8_t a, uint16_t p,
                                       int64_t now = 0) {
  return endat::wire::decode_parameter_reply(
      e.transact(endat::wire::encode_master_frame({m, a, p}), now).reply);
}

endat::ManufacturerWords manufacturer_words(const EnDatEncoder& e) {
  endat::ManufacturerWords w{};
  for (unsigned i = 0; i < 48; ++i) {
    w[i] = *e.word(endat::manufacturer_page_mrs(i), 0, static_cast<uint8_t>(i % 16));
  }
  return w;
}

}  // namespace

TEST_CASE("Default encoder file describes a 25-bit, 4096-revolution EnDat 2.2 encoder",
          "[endat][sim][encoder]") {
  const auto loaded = load_encoder_description(DS1928_SOURCE_DIR "/config/encoder-default.yaml");
  INFO(loaded.error);
  REQUIRE(loaded.description);
  EnDatEncoder enc(*loaded.description);
  const auto w = manufacturer_words(enc);
  const auto id = endat::decode_identification(w);
  REQUIRE(id);
  CHECK(id->command_set == endat::CommandSet::EnDat22);
  CHECK(id->type == endat::EncoderType::Rotary);
  CHECK(id->position_bits == 37);
  CHECK(id->steps_per_revolution == (1u << 25));
  CHECK(id->revolutions == 4096);
  CHECK(id->signal_periods == 2048);
  CHECK(id->id.to_string() == "1080790-02");
  CHECK(id->serial.to_string() == "S36845217");
  CHECK(id->version_word == 0x0022);
  // Checksum word: the 16-bit sum of words 0..47 is zero.
  uint16_t sum = 0;
  for (uint16_t x : w) sum = static_cast<uint16_t>(sum + x);
  CHECK(sum == 0);
  // The file and the built-in default agree on every manufacturer word.
  CHECK(manufacturer_words(EnDatEncoder{}) == w);
  CHECK(enc.word(0xA7, 0, 6) == 3582);
  CHECK(enc.description().timing.write_parameter_ns == 12'000'000);
  CHECK(enc.description().areas.at(0xA9).writable);
  CHECK_FALSE(enc.description().areas.at(0xA1).writable);
  CHECK(enc.description().areas.at(0xB1).blocks == 4);
}

TEST_CASE("Encoder YAML errors name file, line and key", "[endat][sim][encoder]") {
  auto bad = [](const char* yaml) { return parse_encoder_description(yaml, "enc.yaml").error; };
  CHECK(bad("endat: 2.2\nbogus: 1\n").find("enc.yaml:2:1: encoder.bogus: unknown key") == 0);
  CHECK(bad("endat: 3.0\n").find("enc.yaml:1:8: endat: expected 2.1 or 2.2") == 0);
  CHECK(bad("revolutions: 0x10000\n").find("revolutions: number out of range") !=
        std::string::npos);
  CHECK(bad("steps_per_revolution: lots\n").find("steps_per_revolution: not a number") !=
        std::string::npos);
  CHECK(bad("areas:\n  0x40: {writable: true}\n").find("not a memory area") != std::string::npos);
  CHECK(bad("areas:\n  0xA9: {words: [1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17]}\n")
            .find("more words than the area holds") != std::string::npos);
  CHECK(bad("position_bits: 30\n").find("needs 37 bits") != std::string::npos);
  CHECK(bad("faults: {crc_error_rate: 2}\n").find("faults.crc_error_rate: must be 0..1") !=
        std::string::npos);
  CHECK(bad("a: [1,\n").find("enc.yaml:") == 0);
  CHECK(load_encoder_description("/nonexistent/enc.yaml").error ==
        "/nonexistent/enc.yaml: cannot open");
  const auto ok = parse_encoder_description(
      "endat: 2.1\ntype: linear\nposition_bits: 30\nareas:\n  0xB1: {writable: true, blocks: 2, "
      "words_per_block: 8, words: {9: 0x55}}\n");
  INFO(ok.error);
  REQUIRE(ok.description);
  CHECK(ok.description->command_set == endat::CommandSet::EnDat21);
  CHECK(ok.description->areas.count(0xBD) == 0);
  EnDatEncoder e(*ok.description);
  CHECK(e.word(0xB1, 1, 1) == 0x55);
  CHECK_FALSE(e.word(0xB1, 2, 0));
}

TEST_CASE("Encoder memory over the wire: select, read, write, protection",
          "[endat][sim][encoder]") {
  EnDatEncoder e;
  // Reading without a selected area: no answer.
  CHECK(tx(e, Mode::SendParameter, 0, 0).error() == endat::Errc::no_response);
  auto sel = tx(e, Mode::SelectMemoryArea, 0xA1, 0);
  REQUIRE(sel);
  CHECK(sel->address == 0xA1);
  auto r13 = tx(e, Mode::SendParameter, 13, 0);
  REQUIRE(r13);
  CHECK(r13->address == 13);
  CHECK((r13->value & 0x3F) == 37);
  CHECK(tx(e, Mode::SendParameter, 16, 0).error() == endat::Errc::no_response);  // past the page

  // Protected: the encoder echoes, the word stays.
  const uint16_t before = *e.word(0xA1, 0, 13);
  auto w = tx(e, Mode::ReceiveParameter, 13, 0x1234);
  REQUIRE(w);
  CHECK(w->value == 0x1234);
  CHECK(e.word(0xA1, 0, 13) == before);

  // Writable OEM area.
  REQUIRE(tx(e, Mode::SelectMemoryArea, 0xAB, 0));
  REQUIRE(tx(e, Mode::ReceiveParameter, 5, 0xCAFE));
  CHECK(e.word(0xAB, 0, 5) == 0xCAFE);
  CHECK(tx(e, Mode::SendParameter, 5, 0)->value == 0xCAFE);

  // Unknown area, or a block the area does not have: no answer.
  CHECK(tx(e, Mode::SelectMemoryArea, 0xA2, 0).error() == endat::Errc::no_response);
  CHECK(tx(e, Mode::SelectMemoryArea, 0xA9, 1).error() == endat::Errc::no_response);
  REQUIRE(tx(e, Mode::SelectMemoryArea, 0xB1, 3));

  // Processing times as described, scaled.
  EncoderDescription d = default_encoder_description();
  d.timing.scale = 0.5;
  EnDatEncoder fast(d);
  const auto sel_resp =
      fast.transact(endat::wire::encode_master_frame({Mode::SelectMemoryArea, 0xA9, 0}), 0);
  CHECK(sel_resp.processing_ns == 1'000'000);
  const auto wr =
      fast.transact(endat::wire::encode_master_frame({Mode::ReceiveParameter, 0, 1}), 0);
  CHECK(wr.processing_ns == 6'000'000);
}

TEST_CASE("Encoder status words: write 0 to clear, persistent conditions come back",
          "[endat][sim][encoder]") {
  EnDatEncoder e;
  e.set_battery_warning(true);
  REQUIRE(tx(e, Mode::SelectMemoryArea, 0xB9, 0));
  CHECK(tx(e, Mode::SendParameter, 1, 0)->value == 0x0008);
  REQUIRE(tx(e, Mode::ReceiveParameter, 1, 0));
  CHECK(tx(e, Mode::SendParameter, 1, 0)->value == 0x0008);  // still low
  e.set_battery_warning(false);
  REQUIRE(tx(e, Mode::ReceiveParameter, 1, 0));
  CHECK(tx(e, Mode::SendParameter, 1, 0)->value == 0x0000);
  // Words 2-3 are protected by default.
  REQUIRE(tx(e, Mode::ReceiveParameter, 2, 0x00FF));
  CHECK(e.word(0xB9, 0, 2) == 0);
}

TEST_CASE("Encoder position frames, reset and 2.1 behaviour", "[endat][sim][encoder]") {
  EnDatEncoder e;
  e.set_position(0x12'3456'789A);
  const auto f21 = e.transact(endat::wire::encode_master_frame({Mode::SendPosition}), 0).reply;
  auto p21 =
      endat::wire::decode_position_reply(f21, {endat::CommandSet::EnDat21, 37, false, false});
  REQUIRE(p21);
  CHECK(p21->position == 0x12'3456'789A);
  CHECK_FALSE(p21->f1);
  const auto f22 = e.transact(endat::wire::encode_master_frame({Mode::PositionAddInfo}), 0).reply;
  auto p22 =
      endat::wire::decode_position_reply(f22, {endat::CommandSet::EnDat22, 37, false, false});
  REQUIRE(p22);
  CHECK(p22->f2);
  // Position error: F1 set, F2 cleared.
  e.set_position_error(true);
  p22 = endat::wire::decode_position_reply(
      e.transact(endat::wire::encode_master_frame({Mode::PositionAddInfo}), 0).reply,
      {endat::CommandSet::EnDat22, 37, false, false});
  REQUIRE(p22);
  CHECK(p22->f1);
  CHECK_FALSE(p22->f2);
  // Positions wrap to the position bits.
  e.set_position(~uint64_t{0});
  CHECK(e.position() == (uint64_t{1} << 37) - 1);

  // Reset: echo now, deaf for the reset time, selection gone afterwards.
  REQUIRE(tx(e, Mode::SelectMemoryArea, 0xA9, 0, 0));
  auto reset = e.transact(endat::wire::encode_master_frame({Mode::ReceiveReset, 0, 0}), 1000);
  CHECK(reset.processing_ns == 50'000'000);
  CHECK(endat::wire::decode_parameter_reply(reset.reply).has_value());
  CHECK(e.transact(endat::wire::encode_master_frame({Mode::SendPosition}), 1000 + 49'000'000)
            .reply.empty());
  CHECK_FALSE(e.transact(endat::wire::encode_master_frame({Mode::SendPosition}), 1000 + 50'000'000)
                  .reply.empty());
  CHECK(tx(e, Mode::SendParameter, 0, 0, 60'000'000).error() == endat::Errc::no_response);

  // An EnDat 2.1 encoder does not answer 2.2 modes.
  EncoderDescription d = default_encoder_description();
  d.command_set = endat::CommandSet::EnDat21;
  EnDatEncoder old(d);
  CHECK(old.transact(endat::wire::encode_master_frame({Mode::PositionAddInfo}), 0).reply.empty());
  CHECK_FALSE(
      old.transact(endat::wire::encode_master_frame({Mode::SendPosition}), 0).reply.empty());
}

TEST_CASE("Encoder faults: injected CRC errors and silence", "[endat][sim][encoder]") {
  EnDatEncoder e;
  e.inject_crc_errors(2);
  CHECK(tx(e, Mode::SelectMemoryArea, 0xA1, 0).error() == endat::Errc::crc_mismatch);
  CHECK(tx(e, Mode::SelectMemoryArea, 0xA1, 0).error() == endat::Errc::crc_mismatch);
  CHECK(tx(e, Mode::SelectMemoryArea, 0xA1, 0).has_value());
  CHECK(e.corrupted_replies() == 2);
  e.inject_no_response(1);
  CHECK(tx(e, Mode::SendParameter, 0, 0).error() == endat::Errc::no_response);
  CHECK(tx(e, Mode::SendParameter, 0, 0).has_value());
  // A rate: roughly that share of replies is corrupted, reproducibly.
  e.set_crc_error_rate(0.25);
  int bad = 0;
  for (int i = 0; i < 4000; ++i) bad += tx(e, Mode::SendParameter, 0, 0).has_value() ? 0 : 1;
  CHECK(bad > 800);
  CHECK(bad < 1200);
}
