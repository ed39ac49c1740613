// The FM254 object codec: the datasheet's offsets with exact bytes, both byte orders, lengths
// refused, and random round trips.
#include <catch2/catch.hpp>
#include <random>

#include "canio/object_codec.hpp"

using namespace ds1928;
using namespace ds1928::canio;

TEST_CASE("Object codec: input objects at the datasheet offsets, little endian", "[canio][codec]") {
  ModuleInputs in;
  in.position_hw = 0x11223344;
  in.position_lw = 0x55667788;
  in.input_sequence = 0x9A;
  in.rx_bytes = {0xB1, 0xB2, 0xB3, 0xB4, 0xB5, 0xB6 /* not carried under FM254 */};
  in.error_info = 0x10;
  in.pos_cycle = -3;
  CanObject pos{}, status{};
  pack_position_object(in, ByteOrder::Little, pos);
  pack_status_object(in, status);
  // PositionHW 0–3, PositionLW 4–7.
  CHECK(pos == CanObject{0x44, 0x33, 0x22, 0x11, 0x88, 0x77, 0x66, 0x55});
  // InputSequence 8, RxByte1–5 9–13, ErrorInfo 14, PosCycle 15.
  CHECK(status == CanObject{0x9A, 0xB1, 0xB2, 0xB3, 0xB4, 0xB5, 0x10, 0xFD});

  ModuleInputs back;
  back.pos_time_us = 77;  // FM254 carries no PosTime: cleared
  REQUIRE(unpack_position_object(pos, ByteOrder::Little, back));
  REQUIRE(unpack_status_object(status, back));
  CHECK(back.position_hw == 0x11223344);
  CHECK(back.position_lw == 0x55667788);
  CHECK(back.input_sequence == 0x9A);
  CHECK(back.rx_bytes[4] == 0xB5);
  CHECK(back.rx_bytes[5] == 0);
  CHECK(back.error_info == 0x10);
  CHECK(back.pos_cycle == -3);
  CHECK(back.pos_time_us == 0);
}

TEST_CASE("Object codec: big endian positions", "[canio][codec]") {
  ModuleInputs in;
  in.position_hw = 0x01020304;
  in.position_lw = 0xA0B0C0D0;
  CanObject pos{};
  pack_position_object(in, ByteOrder::Big, pos);
  CHECK(pos == CanObject{0x01, 0x02, 0x03, 0x04, 0xA0, 0xB0, 0xC0, 0xD0});
  ModuleInputs back;
  REQUIRE(unpack_position_object(pos, ByteOrder::Big, back));
  CHECK(back.position_lw == 0xA0B0C0D0);
  // Read with the wrong order, the same bytes give another position: the order matters.
  REQUIRE(unpack_position_object(pos, ByteOrder::Little, back));
  CHECK(back.position_lw == 0xD0C0B0A0);
}

TEST_CASE("Object codec: output object at the datasheet offsets", "[canio][codec]") {
  ModuleOutputs out;
  out.output_sequence = 0x81;
  out.tx_bytes = {1, 2, 3, 4, 5, 6 /* not carried */};
  out.ack_error_info = 0x40;
  CanObject bytes;
  bytes.fill(0xEE);
  pack_output_object(out, bytes);
  // OutputSequence 0, TxByte1–5 1–5, AckErrorInfo 6, byte 7 unused (0).
  CHECK(bytes == CanObject{0x81, 1, 2, 3, 4, 5, 0x40, 0});
  ModuleOutputs back;
  REQUIRE(unpack_output_object(bytes, back));
  CHECK(back.output_sequence == 0x81);
  CHECK(back.tx_bytes[4] == 5);
  CHECK(back.tx_bytes[5] == 0);
  CHECK(back.ack_error_info == 0x40);
  REQUIRE(unpack_output_object(std::span<const uint8_t>(bytes.data(), 7), back));  // 7 used
}

TEST_CASE("Object codec: wrong lengths are refused and change nothing", "[canio][codec]") {
  const std::array<uint8_t, 9> long_bytes{1, 2, 3, 4, 5, 6, 7, 8, 9};
  ModuleInputs in;
  in.position_lw = 42;
  for (std::size_t len : {0u, 1u, 7u, 9u}) {
    INFO("length " << len);
    const std::span<const uint8_t> b(long_bytes.data(), len);
    CHECK_FALSE(unpack_position_object(b, ByteOrder::Little, in));
    CHECK_FALSE(unpack_status_object(b, in));
    CHECK(in.position_lw == 42);
  }
  ModuleOutputs out;
  CHECK_FALSE(unpack_output_object(std::span<const uint8_t>(long_bytes.data(), 6), out));
  CHECK_FALSE(unpack_output_object(long_bytes, out));
}

TEST_CASE("Object codec: random round trips in both byte orders", "[canio][codec]") {
  std::mt19937_64 rng(1928);
  for (int i = 0; i < 20000; ++i) {
    const ByteOrder order = (i & 1) ? ByteOrder::Big : ByteOrder::Little;
    ModuleInputs in;
    in.position_hw = static_cast<uint32_t>(rng());
    in.position_lw = static_cast<uint32_t>(rng());
    in.input_sequence = static_cast<uint8_t>(rng());
    for (std::size_t k = 0; k < 5; ++k) in.rx_bytes[k] = static_cast<uint8_t>(rng());
    in.error_info = static_cast<uint8_t>(rng());
    in.pos_cycle = static_cast<int8_t>(rng());
    CanObject a{}, b{};
    pack_position_object(in, order, a);
    pack_status_object(in, b);
    ModuleInputs back;
    REQUIRE(unpack_position_object(a, order, back));
    REQUIRE(unpack_status_object(b, back));
    REQUIRE(back.position_hw == in.position_hw);
    REQUIRE(back.position_lw == in.position_lw);
    REQUIRE(back.input_sequence == in.input_sequence);
    REQUIRE(std::equal(in.rx_bytes.begin(), in.rx_bytes.begin() + 5, back.rx_bytes.begin()));
    REQUIRE(back.error_info == in.error_info);
    REQUIRE(back.pos_cycle == in.pos_cycle);

    ModuleOutputs out;
    out.output_sequence = static_cast<uint8_t>(rng());
    for (std::size_t k = 0; k < 5; ++k) out.tx_bytes[k] = static_cast<uint8_t>(rng());
    out.ack_error_info = static_cast<uint8_t>(rng());
    CanObject o{};
    pack_output_object(out, o);
    ModuleOutputs oback;
    REQUIRE(unpack_output_object(o, oback));
    REQUIRE(oback.output_sequence == out.output_sequence);
    REQUIRE(std::equal(out.tx_bytes.begin(), out.tx_bytes.begin() + 5, oback.tx_bytes.begin()));
    REQUIRE(oback.ack_error_info == out.ack_error_info);
    REQUIRE(o[7] == 0);
  }
}
