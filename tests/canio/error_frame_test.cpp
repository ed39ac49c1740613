// SocketCAN error frames: the kernel's own examples (what sja1000 / can-dev send) decode to the
// right event and state, and random events survive encode → decode.
#include <linux/can.h>
#include <linux/can/error.h>

#include <catch2/catch.hpp>
#include <cstring>
#include <random>
#include <string>

#include "can/can_error_frame.hpp"

using namespace ds1928::canio;

namespace {

// An error frame as the kernel hands it to a CAN_RAW socket: can_id with CAN_ERR_FLAG, dlc 8.
CanFrame kernel_error_frame(uint32_t can_id, std::array<uint8_t, 8> data) {
  CanFrame f;
  REQUIRE((can_id & CAN_ERR_FLAG) != 0);
  f.error = true;
  f.id = can_id & CAN_ERR_MASK;
  f.dlc = CAN_ERR_DLC;
  f.data = data;
  return f;
}

std::string text(const CanErrorEvent& e) {
  char buf[256];
  describe(e, buf, sizeof buf);
  return buf;
}

}  // namespace

TEST_CASE("error classes match linux/can/error.h", "[canio][error]") {
  STATIC_REQUIRE(err_class::kTxTimeout == CAN_ERR_TX_TIMEOUT);
  STATIC_REQUIRE(err_class::kLostArbitration == CAN_ERR_LOSTARB);
  STATIC_REQUIRE(err_class::kController == CAN_ERR_CRTL);
  STATIC_REQUIRE(err_class::kProtocol == CAN_ERR_PROT);
  STATIC_REQUIRE(err_class::kTransceiver == CAN_ERR_TRX);
  STATIC_REQUIRE(err_class::kNoAck == CAN_ERR_ACK);
  STATIC_REQUIRE(err_class::kBusOff == CAN_ERR_BUSOFF);
  STATIC_REQUIRE(err_class::kBusError == CAN_ERR_BUSERROR);
  STATIC_REQUIRE(err_class::kRestarted == CAN_ERR_RESTARTED);
  STATIC_REQUIRE(err_class::kCounters == CAN_ERR_CNT);
  STATIC_REQUIRE(err_ctrl::kRxWarning == CAN_ERR_CRTL_RX_WARNING);
  STATIC_REQUIRE(err_ctrl::kTxPassive == CAN_ERR_CRTL_TX_PASSIVE);
  STATIC_REQUIRE(err_ctrl::kActive == CAN_ERR_CRTL_ACTIVE);
  STATIC_REQUIRE(err_prot::kStuff == CAN_ERR_PROT_STUFF);
  STATIC_REQUIRE(err_prot::kTx == CAN_ERR_PROT_TX);
}

TEST_CASE("bus-off error frame (can_bus_off) decodes to bus-off", "[canio][error]") {
  // drivers/net/can/dev/dev.c can_change_state → CAN_ERR_BUSOFF with the counters.
  const auto f =
      kernel_error_frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF | CAN_ERR_CNT, {0, 0, 0, 0, 0, 0, 255, 0});
  auto e = decode_error_frame(f);
  REQUIRE(e);
  CHECK(e->bus_off);
  CHECK_FALSE(e->restarted);
  CHECK(e->counters_flagged);
  CHECK(e->tx_error_count == 255);
  REQUIRE(e->state_change());
  CHECK(*e->state_change() == CanState::BusOff);
  CHECK(text(*e) == "bus-off; TEC 255 REC 0");
}

TEST_CASE("controller warning / passive / active frames move the state", "[canio][error]") {
  SECTION("tx warning (TEC 96)") {
    auto e =
        decode_error_frame(kernel_error_frame(CAN_ERR_FLAG | CAN_ERR_CRTL | CAN_ERR_CNT,
                                              {0, CAN_ERR_CRTL_TX_WARNING, 0, 0, 0, 0, 96, 3}));
    REQUIRE(e);
    CHECK(e->controller);
    CHECK(e->controller_status == CAN_ERR_CRTL_TX_WARNING);
    CHECK(*e->state_change() == CanState::ErrorWarning);
    CHECK(e->rx_error_count == 3);
    CHECK(text(*e) == "controller: tx-warning; TEC 96 REC 3");
  }
  SECTION("rx passive (REC 128)") {
    auto e = decode_error_frame(kernel_error_frame(
        CAN_ERR_FLAG | CAN_ERR_CRTL, {0, CAN_ERR_CRTL_RX_PASSIVE, 0, 0, 0, 0, 0, 128}));
    REQUIRE(e);
    CHECK(*e->state_change() == CanState::ErrorPassive);
    CHECK_FALSE(e->counters_flagged);
    CHECK(e->rx_error_count == 128);  // older drivers fill the counters without CAN_ERR_CNT
  }
  SECTION("back to error-active") {
    auto e = decode_error_frame(kernel_error_frame(CAN_ERR_FLAG | CAN_ERR_CRTL,
                                                   {0, CAN_ERR_CRTL_ACTIVE, 0, 0, 0, 0, 0, 0}));
    REQUIRE(e);
    CHECK(*e->state_change() == CanState::ErrorActive);
  }
  SECTION("rx overflow changes no state") {
    auto e = decode_error_frame(kernel_error_frame(
        CAN_ERR_FLAG | CAN_ERR_CRTL, {0, CAN_ERR_CRTL_RX_OVERFLOW, 0, 0, 0, 0, 0, 0}));
    REQUIRE(e);
    CHECK_FALSE(e->state_change());
    CHECK(text(*e) == "controller: rx-overflow");
  }
}

TEST_CASE("restarted, protocol, ACK and TX timeout frames", "[canio][error]") {
  auto restarted = decode_error_frame(kernel_error_frame(CAN_ERR_FLAG | CAN_ERR_RESTARTED, {}));
  REQUIRE(restarted);
  CHECK(restarted->restarted);
  CHECK(*restarted->state_change() == CanState::ErrorActive);

  // sja1000 bus error on transmission: stuff error in the data section, no ACK.
  auto prot = decode_error_frame(kernel_error_frame(
      CAN_ERR_FLAG | CAN_ERR_PROT | CAN_ERR_BUSERROR | CAN_ERR_ACK,
      {0, 0, CAN_ERR_PROT_STUFF | CAN_ERR_PROT_TX, CAN_ERR_PROT_LOC_DATA, 0, 0, 8, 0}));
  REQUIRE(prot);
  CHECK(prot->protocol);
  CHECK(prot->protocol_type == (CAN_ERR_PROT_STUFF | CAN_ERR_PROT_TX));
  CHECK(prot->protocol_location == CAN_ERR_PROT_LOC_DATA);
  CHECK(prot->no_ack);
  CHECK(prot->bus_error);
  CHECK_FALSE(prot->state_change());
  CHECK(text(*prot) ==
        "no ACK on transmission; protocol: stuff error at data section (tx); bus error");

  auto timeout = decode_error_frame(kernel_error_frame(CAN_ERR_FLAG | CAN_ERR_TX_TIMEOUT, {}));
  REQUIRE(timeout);
  CHECK(timeout->tx_timeout);
  CHECK(text(*timeout) == "TX timeout");
}

TEST_CASE("malformed error frames are named", "[canio][error]") {
  CanFrame data;
  data.id = 0x181;
  data.dlc = 8;
  CHECK(decode_error_frame(data).error() == CanError::kNotAnErrorFrame);
  CanFrame shortf;
  shortf.error = true;
  shortf.id = CAN_ERR_BUSOFF;
  shortf.dlc = 4;
  CHECK(decode_error_frame(shortf).error() == CanError::kErrorFrameLength);
  CanFrame unknown;
  unknown.error = true;
  unknown.dlc = 8;
  unknown.id = 0x400;
  CHECK(decode_error_frame(unknown).error() == CanError::kUnknownErrorClass);
}

TEST_CASE("random error events survive encode and decode", "[canio][error][random]") {
  std::mt19937_64 rng(0xCA11);
  for (int i = 0; i < 20000; ++i) {
    const uint64_t r = rng();
    CanErrorEvent e;
    e.tx_timeout = r & 1;
    e.lost_arbitration = r & 2;
    e.controller = r & 4;
    e.protocol = r & 8;
    e.transceiver = r & 16;
    e.no_ack = r & 32;
    e.bus_off = r & 64;
    e.bus_error = r & 128;
    e.restarted = r & 256;
    e.counters_flagged = r & 512;
    if (e.lost_arbitration) e.arbitration_bit = static_cast<uint8_t>(r >> 10);
    if (e.controller) e.controller_status = static_cast<uint8_t>(r >> 18);
    if (e.protocol) {
      e.protocol_type = static_cast<uint8_t>(r >> 26);
      e.protocol_location = static_cast<uint8_t>(r >> 34);
    }
    if (e.transceiver) e.transceiver_status = static_cast<uint8_t>(r >> 42);
    e.controller_specific = static_cast<uint8_t>(r >> 50);
    e.tx_error_count = static_cast<uint8_t>(rng());
    e.rx_error_count = static_cast<uint8_t>(rng());
    const CanFrame f = encode_error_frame(e);
    REQUIRE(f.error);
    REQUIRE(f.dlc == 8);
    auto d = decode_error_frame(f);
    REQUIRE(d);
    e.classes = f.id;
    REQUIRE(*d == e);
    // Any decoded event with a state is consistent with its flags.
    if (auto s = d->state_change(); s && *s == CanState::BusOff) REQUIRE(d->bus_off);
    char buf[8];
    REQUIRE(describe(*d, buf, sizeof buf) < sizeof buf);  // truncates, never overruns
  }
  // Random frames never crash the decoder and are either decoded or named.
  for (int i = 0; i < 20000; ++i) {
    CanFrame f;
    f.error = rng() & 1;
    f.id = static_cast<uint32_t>(rng()) & (rng() & 1 ? 0x3FFu : 0x1FFF'FFFFu);
    f.dlc = static_cast<uint8_t>(rng() % 10);
    const uint64_t d = rng();
    std::memcpy(f.data.data(), &d, 8);
    auto e = decode_error_frame(f);
    if (!e) {
      const bool named = e.error() == CanError::kNotAnErrorFrame ||
                         e.error() == CanError::kErrorFrameLength ||
                         e.error() == CanError::kUnknownErrorClass;
      REQUIRE(named);
    } else {
      REQUIRE(encode_error_frame(*e).id == f.id);
    }
  }
}
