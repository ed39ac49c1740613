// Identification decoding, names of status bits and MRS codes, temperatures, number parsing.
#include <catch2/catch.hpp>
#include <cstdint>

#include "endat/ident.hpp"
#include "endat/names.hpp"
#include "endat/number.hpp"
#include "x20ds1928/module_image.hpp"

using namespace ds1928::endat;

TEST_CASE("Identification: words of endat.md §4 decode to their fields", "[endat][ident]") {
  ManufacturerWords w{};
  w[8] = 0x0022;
  w[13] = 0xC025;  // bits 5..0 = 37; upper bits must be ignored
  w[14] = 0x8000;  // rotary
  w[15] = 0x0800;  // 2048 signal periods
  w[16] = 0x0000;
  w[17] = 4096;
  w[20] = 0x0000;  // 2^25 steps: low word 0, high word 0x0200
  w[21] = 0x0200;
  w[24] = ('0' << 8) | '2';  // "02"
  w[25] = 0x7DD6;            // 1080790 = 0x107DD6
  w[26] = 0x0010;
  w[27] = (0x4E << 8) | 'S';  // prefix 'S', binary bits 7..0 = 0x4E
  w[28] = 0xBC61;             // bits 23..8
  w[29] = ('A' << 8) | 0x00;  // bits 31..24 = 0, suffix 'A'
  w[36] = 0x001F;
  w[37] = 0x0001;
  auto id = decode_identification(w);
  REQUIRE(id);
  CHECK(id->command_set == CommandSet::EnDat22);
  CHECK(id->version_word == 0x0022);
  CHECK(id->type == EncoderType::Rotary);
  CHECK(id->position_bits == 37);
  CHECK(id->signal_periods == 2048);
  CHECK(id->revolutions == 4096);
  CHECK(id->multiturn());
  CHECK(id->steps_per_revolution == (1u << 25));
  CHECK(id->id.binary == 1080790);
  CHECK(id->id.to_string() == "1080790-02");
  CHECK(id->serial.binary == 0x00BC614E);  // 12345678
  CHECK(id->serial.to_string() == "S12345678A");
  CHECK(id->warnings_supported == 0x001F);

  ManufacturerWords again{};
  again[13] = 0xC000;  // upper bits of word 13 and 14 survive encoding
  encode_identification(*id, again);
  for (unsigned i : {8u, 14u, 15u, 16u, 17u, 20u, 21u, 24u, 25u, 26u, 27u, 28u, 29u, 36u, 37u}) {
    CHECK(again[i] == w[i]);
  }
  CHECK(again[13] == 0xC025);
}

TEST_CASE("Identification: command set word", "[endat][ident]") {
  CHECK(command_set_from_word(0x0001) == CommandSet::EnDat22);
  CHECK(command_set_from_word(0xFFFD) == CommandSet::EnDat22);
  CHECK(command_set_from_word(0x0000) == CommandSet::EnDat21);
  CHECK(command_set_from_word(0x0003) == CommandSet::EnDat21);
  CHECK(command_set_from_word(0x0002) == CommandSet::EnDat21);
}

TEST_CASE("Identification: inconsistent words are refused", "[endat][ident]") {
  ManufacturerWords w{};
  w[13] = 0;  // no position bits
  w[14] = 0;  // linear
  CHECK(decode_identification(w).error() == Errc::invalid_identification);
  w[13] = 49;
  CHECK(decode_identification(w).error() == Errc::invalid_identification);
  w[13] = 24;  // linear, 24 bits: fine
  CHECK(decode_identification(w).has_value());
  w[14] = 0x8000;  // rotary without steps per revolution
  CHECK(decode_identification(w).error() == Errc::invalid_identification);
  w[21] = 0x0100;  // 2^24 steps, singleturn, 24 bits: fine
  CHECK(decode_identification(w).has_value());
  w[17] = 4096;  // multiturn needs 36 bits
  CHECK(decode_identification(w).error() == Errc::invalid_identification);
  w[13] = 36;
  CHECK(decode_identification(w).has_value());
  CHECK(bits_for(1) == 0);
  CHECK(bits_for(4096) == 12);
  CHECK(bits_for(4097) == 13);
  CHECK(manufacturer_page_mrs(13) == 0xA1);
  CHECK(manufacturer_page_mrs(21) == 0xA3);
  CHECK(manufacturer_page_mrs(37) == 0xA5);
}

TEST_CASE("Status bit names", "[endat][names]") {
  using V = std::vector<std::string>;
  CHECK(endat_error_names(0) == V{});
  // The names are the error table's (x20ds1928/error_bits.hpp); reserved bits by register.
  CHECK(endat_error_names(0x0041) == V{"Lighting", "Battery"});
  CHECK(endat_error_names(0x0104) == V{"PositionValue", "EnDatError reserved bit 8"});
  CHECK(endat_warning_names(0x0008) == V{"BatteryCharge"});
  CHECK(endat_warning_names(0x0012) == V{"Temperature", "ReferencePoint"});
}

TEST_CASE("MRS names", "[endat][names]") {
  CHECK(mrs_name(0xA1).find("manufacturer") != std::string_view::npos);
  CHECK(mrs_name(0xA9).find("OEM") != std::string_view::npos);
  CHECK(mrs_name(0xB9) == "operating status");
  CHECK(mrs_name(0xBD).find("EnDat 2.2") != std::string_view::npos);
  CHECK(mrs_name(0x4C).find("temperature 1") != std::string_view::npos);
  CHECK(mrs_name(0x5B).find("time stamp") != std::string_view::npos);
  CHECK(mrs_name(0x00).empty());
  CHECK(mrs_name(0xA2).empty());
}

TEST_CASE("Temperature words in 0.1 K", "[endat][names]") {
  CHECK(temperature_celsius(2732) == Approx(0.0).margin(1e-9));
  CHECK(temperature_celsius(3132) == Approx(40.0));
  CHECK(temperature_celsius(0) == Approx(-273.2));
  CHECK(temperature_raw(40.0) == 3132);
  CHECK(temperature_raw(-300.0) == 0);
  CHECK(temperature_raw(1e9) == 65535);
}

TEST_CASE("Numbers in hex or decimal with range checks", "[endat][number]") {
  CHECK(*parse_number("0xA9", 0, 255) == 0xA9);
  CHECK(*parse_number("0Xa9", 0, 255) == 0xA9);
  CHECK(*parse_number("169", 0, 255) == 169);
  CHECK(*parse_number("0", 0, 255) == 0);
  CHECK(*parse_number("007", 0, 255) == 7);
  CHECK(parse_number("256", 0, 255).error() == Errc::number_out_of_range);
  CHECK(parse_number("0x100", 0, 255).error() == Errc::number_out_of_range);
  CHECK(parse_number("3", 4, 9).error() == Errc::number_out_of_range);
  CHECK(parse_number("", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number("0x", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number("-1", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number("+1", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number(" 1", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number("12a", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number("0xG", 0, 255).error() == Errc::invalid_number);
  CHECK(parse_number("99999999999999999999999", 0, UINT64_MAX).error() ==
        Errc::number_out_of_range);
  CHECK(*parse_number("18446744073709551615", 0, UINT64_MAX) == UINT64_MAX);
  CHECK(*parse_u16("0xFFFF") == 0xFFFF);
  CHECK(parse_u16("65536").error() == Errc::number_out_of_range);
  CHECK(*parse_u8("0xa1") == 0xA1);
}

TEST_CASE("Words read from the encoder described for humans", "[endat][names]") {
  CHECK(describe_word(0xA1, 13, 0x0025) == "clock pulses for the position value: 37 bits");
  CHECK(describe_word(0xA1, 14, 0x8000) == "encoder type: rotary");
  CHECK(describe_word(0xA3, 1, 0) == "distinguishable revolutions: singleturn");  // word 17
  CHECK(describe_word(0xA3, 8, ('0' << 8) | '2') == "ID number, ASCII part: \"02\"");
  CHECK(describe_word(0xA5, 5, 0x0001) == "EnDat command set: EnDat 2.2");  // word 37
  CHECK(describe_word(0xA5, 15, 0xABCD) == "checksum");
  CHECK(describe_word(0xA1, 0, 0).empty());
  CHECK(describe_word(0xB9, 0, 0x0041) == "errors: light source failed, battery must be replaced");
  CHECK(describe_word(0xB9, 1, 0) == "warnings: none");
  CHECK(describe_word(0xA7, 6, 3582) == "temperature warning threshold: 85.0 °C");
  CHECK(describe_word(0x4C, 0, 3147) == "additional information 1: temperature 1: 41.5 °C");
  CHECK(describe_word(0xA9, 3, 0x1234).empty());
  CHECK(manufacturer_word_name(20) == "measuring steps per revolution, low word");
  CHECK(manufacturer_word_name(0).empty());
}
