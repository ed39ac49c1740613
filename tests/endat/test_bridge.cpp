// Module bridge + encoder round trips: identification registers, read/write/protected write,
// blocks, additional information, reset, acknowledge, rescan, faults, timing, determinism.
#include <catch2/catch.hpp>
#include <cstdint>
#include <map>
#include <random>
#include <vector>

#include "endat/command.hpp"
#include "endat/names.hpp"
#include "sim/endat_bridge.hpp"
#include "x20ds1928/module_image.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using namespace ds1928::sim;
using endat::Errc;
using endat::Request;

namespace {

constexpr int64_t kMs = 1'000'000;

EncoderDescription fast_description(double scale = 0.01) {
  EncoderDescription d = default_encoder_description();
  d.timing.scale = scale;
  return d;
}

BridgeConfig quiet_config() {
  BridgeConfig c;
  c.status_refresh_ns = 0;  // only event-driven status reads: exact timings in tests
  return c;
}

// Sends one request and polls in 100 µs steps until the reply is there.
struct Harness {
  EnDatBridge bridge;
  int64_t now = 0;

  explicit Harness(EncoderDescription d = fast_description(), BridgeConfig c = quiet_config())
      : bridge(EnDatEncoder(std::move(d)), c) {
    REQUIRE_FALSE(bridge.power_up(now));
    now = bridge.busy_until_ns();
  }

  std::vector<uint8_t> raw(std::span<const uint8_t> msg, int64_t limit_ns = 2000 * kMs) {
    REQUIRE(bridge.submit(msg, now));
    const int64_t start = now;
    while (now - start < limit_ns) {
      if (auto r = bridge.poll(now)) return {r->bytes().begin(), r->bytes().end()};
      now += 100'000;
    }
    FAIL("no reply");
    return {};
  }

  Result<endat::Reply> run(const Request& r) {
    const auto msg = endat::encode_request(r, endat::CommandSet::EnDat22);
    REQUIRE(msg);
    const auto bytes = raw(msg->span());
    return endat::decode_reply(r, bytes);
  }
};

}  // namespace

TEST_CASE("Bridge: identification registers mirror the encoder at power-up",
          "[endat][sim][bridge]") {
  EncoderDescription d = fast_description();
  d.areas[0xBD].words[1] = 0x1111;
  d.areas[0xBD].words[63] = 0x6363;
  Harness h(d);
  const EnDatEncoder& enc = h.bridge.encoder();
  const auto& id = h.bridge.identification();
  REQUIRE(id);
  CHECK(id->position_bits == 37);
  CHECK(id->command_set == endat::CommandSet::EnDat22);
  CHECK(h.bridge.ident().valid);
  for (unsigned n = 4; n < 48; ++n) {
    CHECK(h.bridge.read_register(static_cast<uint16_t>(reg::kParamManuf0 + n)) ==
          enc.word(endat::manufacturer_page_mrs(n), 0, static_cast<uint8_t>(n % 16)));
  }
  for (unsigned n = 0; n < 16; ++n) {
    CHECK(h.bridge.read_register(static_cast<uint16_t>(reg::kOperatingParam0 + n)) ==
          enc.word(0xA7, 0, static_cast<uint8_t>(n)));
  }
  for (unsigned n = 1; n < 64; ++n) {
    CHECK(h.bridge.read_register(static_cast<uint16_t>(reg::kParamManufEnDat22_0 + n)) ==
          enc.word(0xBD, 0, static_cast<uint8_t>(n)));
  }
  CHECK(h.bridge.read_register(reg::kParamManufEnDat22_0 + 63) == 0x6363);
  CHECK(h.bridge.read_register(reg::kEnDatError) == 0);
  CHECK_FALSE(h.bridge.read_register(reg::kEnDatMode));
  CHECK_FALSE(h.bridge.read_register(reg::kParamManufEnDat22_0));
  // Positions flow with the identified format.
  h.bridge.set_position(123456789);
  const auto p = h.bridge.read_position(h.now);
  CHECK(p.fresh);
  CHECK(p.steps == 123456789);
  CHECK_FALSE(p.error);
  // The identification read took realistic time: 6 selections and 131 reads of 20 µs each
  // (2 ms scaled by 0.01) plus wire time at 2 MHz.
  CHECK(h.bridge.busy_until_ns() > 2'740'000);
  CHECK(h.bridge.busy_until_ns() < 10 * kMs);
  Harness real(fast_description(1.0));
  CHECK(real.bridge.busy_until_ns() > 274 * kMs);
}

TEST_CASE("Bridge: read, write and read back, protected write", "[endat][sim][bridge]") {
  Harness h;
  auto r = h.run(Request::read(0xA1, 13));
  REQUIRE(r);
  CHECK((r->value() & 0x3F) == 37);

  REQUIRE(h.run(Request::write(0xA9, 2, 0xBEEF)));
  auto back = h.run(Request::read(0xA9, 2));
  REQUIRE(back);
  CHECK(back->value() == 0xBEEF);
  CHECK_FALSE(endat::check_readback(0xBEEF, back->value()));
  CHECK(h.bridge.encoder().word(0xA9, 0, 2) == 0xBEEF);

  // A protected area: the write "succeeds" on the wire, the read-back tells the truth.
  const uint16_t before = *h.bridge.encoder().word(0xA3, 0, 5);
  REQUIRE(h.run(Request::write(0xA3, 5, static_cast<uint16_t>(before ^ 0xFFFF))));
  auto prot = h.run(Request::read(0xA3, 5));
  REQUIRE(prot);
  CHECK(prot->value() == before);
  CHECK(endat::check_readback(static_cast<uint16_t>(before ^ 0xFFFF), prot->value()) ==
        Errc::write_not_applied);

  // Outside the area: the encoder stays silent, the module says so.
  CHECK(h.run(Request::read(0xA9, 40)).error() == Errc::module_no_response);
  CHECK(h.run(Request::read(0xA2, 0)).error() == Errc::module_no_response);
  CHECK((h.bridge.error_info() & error_info::kEnDatComError) == 0);
}

TEST_CASE("Bridge: block commands", "[endat][sim][bridge]") {
  EncoderDescription d = fast_description();
  d.areas[0xB1].writable = true;
  Harness h(d);
  REQUIRE(h.run(Request::write_block(0xB1, 3, 15, 0x3F3F)));
  REQUIRE(h.run(Request::write_block(0xB1, 0, 15, 0x0F0F)));
  CHECK(h.run(Request::read_block(0xB1, 3, 15))->value() == 0x3F3F);
  CHECK(h.run(Request::read_block(0xB1, 0, 15))->value() == 0x0F0F);
  CHECK(h.bridge.encoder().word(0xB1, 3, 15) == 0x3F3F);
  CHECK(h.run(Request::read_block(0xB1, 4, 0)).error() == Errc::module_no_response);
}

TEST_CASE("Bridge: additional information words", "[endat][sim][bridge]") {
  EncoderDescription d = fast_description();
  d.temperature_c = 47.3;
  Harness h(d);
  for (unsigned word = 1; word <= 4; ++word) {
    auto r = h.run(Request::read_info(word, 0x4C));
    REQUIRE(r);
    REQUIRE(r->word_count == word);
    CHECK(endat::temperature_celsius(r->value()) == Approx(47.3).margin(0.05));
  }
  h.bridge.set_position(0x0000'1234'5678'9ABC & ((uint64_t{1} << 37) - 1));
  CHECK(h.run(Request::read_info(1, 0x42))->value() == 0x9ABC);
  CHECK(h.run(Request::read_info(2, 0x43))->value() == 0x5678);
  // An AI2 item and a time stamp that advances with the frames.
  auto ts = h.run(Request::read_info(4, 0x5B));
  REQUIRE(ts);
  CHECK(ts->words[3] == ts->words[0] + 3);
  // Positions go back to the plain frame after the command.
  CHECK(h.bridge.read_position(h.now).fresh);
  // "Stop" delivers nothing: the module gives up after its frame budget.
  CHECK(h.run(Request::read_info(1, 0x4F)).error() == Errc::module_no_response);
}

TEST_CASE("Bridge: EnDat 2.1 encoder refuses 2.2 commands, malformed requests",
          "[endat][sim][bridge]") {
  EncoderDescription d = fast_description();
  d.command_set = endat::CommandSet::EnDat21;
  d.areas.erase(0xBD);
  apply_identification(d);
  Harness h(d);
  REQUIRE(h.bridge.identification());
  CHECK(h.bridge.identification()->command_set == endat::CommandSet::EnDat21);
  for (uint8_t cmd = 0x06; cmd <= 0x0B; ++cmd) {
    std::vector<uint8_t> msg{cmd, 0xB1, 0, 0, 0, 0};
    msg.resize(endat::request_size(*endat::command_from_byte(cmd)));
    if (cmd >= 0x08) msg[1] = 0x4C;
    const auto reply = h.raw(msg);
    CHECK(reply == std::vector<uint8_t>{static_cast<uint8_t>(0x80 | cmd), 3});
  }
  CHECK(h.raw(std::vector<uint8_t>{0x04, 0xA9}) == std::vector<uint8_t>{0x84, 4});
  CHECK(h.raw(std::vector<uint8_t>{0x02}) == std::vector<uint8_t>{0x82, 4});
  CHECK(h.raw(std::vector<uint8_t>(40, 0x05)) == std::vector<uint8_t>{0x85, 4});
  CHECK(h.raw(std::vector<uint8_t>{}) == std::vector<uint8_t>{0x80, 4});
  // 2.1 commands work, positions use the 2.1 frame.
  REQUIRE(h.run(Request::write(0xA9, 0, 7)));
  CHECK(h.run(Request::read(0xA9, 0))->value() == 7);
  CHECK(h.bridge.read_position(h.now).fresh);
  CHECK(h.bridge.read_register(reg::kParamManufEnDat22_0 + 1) == 0);
}

TEST_CASE("Bridge: reset takes the encoder's reset time, positions pause without an error",
          "[endat][sim][bridge]") {
  Harness h(fast_description(1.0));  // real timing: 50 ms
  const int64_t start = h.now;
  const auto reply = h.raw(std::vector<uint8_t>{0x00});
  CHECK(reply == std::vector<uint8_t>{0x00});
  CHECK(h.now - start >= 50 * kMs);
  CHECK(h.now - start < 52 * kMs);

  // Positions read while the reset runs get no answer but raise no communication error.
  EnDatBridge& b = h.bridge;
  REQUIRE(b.submit(std::vector<uint8_t>{0x00}, h.now));
  const auto during = b.read_position(h.now + 10 * kMs);
  CHECK_FALSE(during.fresh);
  CHECK(during.error == Errc::no_response);
  CHECK((b.error_info() & error_info::kEnDatComError) == 0);
  while (!b.poll(h.now)) h.now += kMs;
  CHECK(b.read_position(h.now).fresh);
}

TEST_CASE("Bridge: acknowledge, EnDatAck and persistent faults", "[endat][sim][bridge]") {
  Harness h;
  EnDatBridge& b = h.bridge;
  b.encoder().set_battery_warning(true);
  b.encoder().set_position_error(true);
  auto p = b.read_position(h.now);
  CHECK(p.fresh);
  CHECK(p.encoder_error);
  CHECK((b.error_info() & error_info::kEnDatPosError) != 0);
  // The F1 edge makes the module re-read the status words.
  h.now += 10 * kMs;
  (void)b.poll(h.now);
  CHECK(b.endat_error() == 0x0004);
  CHECK(b.endat_warning() == 0x0008);
  CHECK(endat::endat_warning_names(b.endat_warning()) == std::vector<std::string>{"BatteryCharge"});

  // Acknowledge while both persist: both come back.
  REQUIRE(h.run(Request::acknowledge()));
  CHECK(b.endat_error() == 0x0004);
  CHECK(b.endat_warning() == 0x0008);

  // The position fault goes away: acknowledge clears it, the battery warning stays.
  b.encoder().set_position_error(false);
  REQUIRE(h.run(Request::acknowledge()));
  CHECK(b.endat_error() == 0);
  CHECK(b.endat_warning() == 0x0008);
  p = b.read_position(h.now);
  CHECK_FALSE(p.encoder_error);
  // ErrorInfo keeps EnDatPosError latched until AckErrorInfo.
  CHECK((b.error_info() & error_info::kEnDatPosError) != 0);
  b.acknowledge_error_info(error_info::kEnDatPosError);
  CHECK((b.error_info() & error_info::kEnDatPosError) == 0);

  // EnDatAck bit 0 does the same without a Flatstream message.
  b.encoder().set_battery_warning(false);
  b.endat_ack(0x01, h.now);
  h.now += 10 * kMs;
  (void)b.poll(h.now);
  CHECK(b.endat_warning() == 0);
}

TEST_CASE("Bridge: rescan (EnDatAck bit 1) re-reads identification", "[endat][sim][bridge]") {
  Harness h;
  EnDatBridge& b = h.bridge;
  REQUIRE(b.encoder().set_word(0xA5, 0, 4, 0x4242));  // global word 36
  CHECK(b.read_register(reg::kParamManuf0 + 36) != 0x4242);
  b.endat_ack(0x02, h.now);
  CHECK(b.read_register(reg::kParamManuf0 + 36) == 0x4242);
  // A message submitted during the rescan waits for it.
  REQUIRE(b.submit(std::vector<uint8_t>{0x04, 0xA9, 0x00}, h.now));
  CHECK_FALSE(b.poll(h.now + 2 * kMs));
  h.now += 10 * kMs;
  CHECK(b.poll(h.now));
  // A broken identification raises EnDatParSetError.
  REQUIRE(b.encoder().set_word(0xA1, 0, 13, 0));
  b.endat_ack(0x02, h.now);
  CHECK((b.error_info() & error_info::kEnDatParSetError) != 0);
  CHECK_FALSE(b.ident().valid);
}

TEST_CASE("Bridge: CRC errors on the wire", "[endat][sim][bridge]") {
  Harness h;
  EnDatBridge& b = h.bridge;
  SECTION("a single corrupted reply is retried transparently") {
    b.encoder().inject_crc_errors(1);
    CHECK(h.run(Request::read(0xA1, 13)).has_value());
    CHECK(b.stats().retries == 1);
    CHECK((b.error_info() & error_info::kEnDatComError) == 0);
  }
  SECTION("persistent errors: failure reply and EnDatComError") {
    b.encoder().set_crc_error_rate(1.0);
    CHECK(h.run(Request::read(0xA9, 0)).error() == Errc::module_crc_failure);
    CHECK(h.run(Request::write(0xA9, 0, 1)).error() == Errc::module_crc_failure);
    CHECK(h.run(Request::read_info(1, 0x4C)).error() == Errc::module_crc_failure);
    CHECK((b.error_info() & error_info::kEnDatComError) != 0);
    const auto p = b.read_position(h.now);
    CHECK_FALSE(p.fresh);
    CHECK(p.error);
    // Acknowledging while the fault persists does not clear it.
    b.acknowledge_error_info(error_info::kEnDatComError);
    CHECK((b.error_info() & error_info::kEnDatComError) != 0);
    b.encoder().set_crc_error_rate(0.0);
    CHECK(b.read_position(h.now).fresh);
    CHECK((b.error_info() & error_info::kEnDatComError) != 0);  // latched
    b.acknowledge_error_info(error_info::kEnDatComError);
    CHECK((b.error_info() & error_info::kEnDatComError) == 0);
  }
  SECTION("an unplugged encoder") {
    b.encoder().inject_no_response(100);
    CHECK(h.run(Request::read(0xA9, 0)).error() == Errc::module_no_response);
    CHECK(b.read_position(h.now).error == Errc::no_response);
    CHECK((b.error_info() & error_info::kEnDatComError) != 0);
  }
}

TEST_CASE("Bridge: reply timing follows the encoder's processing times", "[endat][sim][bridge]") {
  Harness h(fast_description(1.0));
  EnDatBridge& b = h.bridge;
  h.now = b.busy_until_ns();
  const int64_t t0 = h.now;
  REQUIRE(b.submit(std::vector<uint8_t>{0x04, 0xA9, 0x01}, t0));
  CHECK_FALSE(b.poll(t0 + 3 * kMs));  // select 2 ms + read 2 ms
  auto r = b.poll(t0 + 5 * kMs);
  REQUIRE(r);
  CHECK(r->ready_ns - t0 > 4 * kMs);
  CHECK(r->ready_ns - t0 < 4 * kMs + 200'000);
  // One command at a time.
  REQUIRE(b.submit(std::vector<uint8_t>{0x05, 0xA9, 0x01, 0x02, 0x03}, t0 + 5 * kMs));
  CHECK_FALSE(b.submit(std::vector<uint8_t>{0x00}, t0 + 5 * kMs));
  CHECK_FALSE(b.idle());
  auto w = b.poll(t0 + 20 * kMs);  // select 2 ms + write 12 ms
  REQUIRE(w);
  CHECK(w->ready_ns - (t0 + 5 * kMs) > 14 * kMs);
  CHECK(b.idle());
  // The result does not depend on how often the module polls.
  CHECK(w->ready_ns < t0 + 20 * kMs);
}

TEST_CASE("Bridge: periodic status refresh picks up warnings", "[endat][sim][bridge]") {
  BridgeConfig c;
  c.status_refresh_ns = 100 * kMs;
  Harness h(fast_description(), c);
  h.bridge.encoder().set_battery_warning(true);
  (void)h.bridge.poll(h.now + 50 * kMs);
  CHECK(h.bridge.endat_warning() == 0);
  (void)h.bridge.poll(h.now + 150 * kMs);
  CHECK(h.bridge.endat_warning() == 0x0008);
}

TEST_CASE("Bridge: identical inputs give identical replies and times", "[endat][sim][bridge]") {
  auto run = [] {
    EncoderDescription d = fast_description();
    d.faults.seed = 77;
    Harness h(d);
    h.bridge.encoder().set_crc_error_rate(0.2);
    std::vector<std::vector<uint8_t>> out;
    std::vector<int64_t> times;
    for (int i = 0; i < 30; ++i) {
      const std::vector<uint8_t> msg{0x05, 0xA9, static_cast<uint8_t>(i % 16),
                                     static_cast<uint8_t>(i), 0};
      out.push_back(h.raw(msg));
      out.push_back(h.raw(std::vector<uint8_t>{0x04, 0xA9, static_cast<uint8_t>(i % 16)}));
      times.push_back(h.now);
    }
    return std::make_pair(out, times);
  };
  CHECK(run() == run());
}

TEST_CASE("Bridge: random commands on a lossy wire never yield a wrong value",
          "[endat][sim][bridge][random]") {
  EncoderDescription d = fast_description(0.001);
  d.faults.seed = 5;
  Harness h(d);
  h.bridge.encoder().set_crc_error_rate(0.15);
  // Shadow of what the writable OEM areas hold.
  std::map<std::pair<uint8_t, uint8_t>, uint16_t> shadow;
  for (uint8_t mrs : {0xA9, 0xAB}) {
    for (uint8_t p = 0; p < 16; ++p) shadow[{mrs, p}] = *h.bridge.encoder().word(mrs, 0, p);
  }
  std::mt19937_64 rng(11);
  int values = 0, failures = 0;
  for (int i = 0; i < 400; ++i) {
    const uint8_t mrs = (rng() & 1) ? 0xA9 : 0xAB;
    const auto p = static_cast<uint8_t>(rng() % 16);
    if (rng() % 3 == 0) {
      const auto v = static_cast<uint16_t>(rng());
      const auto r = h.run(Request::write(mrs, p, v));
      if (r) {
        shadow[{mrs, p}] = v;
      } else {
        REQUIRE(r.error() == Errc::module_crc_failure);
        // The encoder may or may not have taken it; learn the truth from the encoder.
        shadow[{mrs, p}] = *h.bridge.encoder().word(mrs, 0, p);
      }
    } else {
      const auto r = h.run(Request::read(mrs, p));
      if (r) {
        ++values;
        REQUIRE(r->value() == shadow[{mrs, p}]);
      } else {
        ++failures;
        REQUIRE(r.error() == endat::Condition::module_failure);
      }
    }
  }
  CHECK(values > 100);
  CHECK(h.bridge.stats().retries > 0);
  INFO("failures: " << failures);
}

TEST_CASE("Bridge: garbage messages get a well-formed reply or a malformed-request failure",
          "[endat][sim][bridge][fuzz]") {
  Harness h(fast_description(0.001));
  std::mt19937_64 rng(3);
  for (int i = 0; i < 2000; ++i) {
    std::vector<uint8_t> msg(rng() % 8);
    for (auto& b : msg) b = static_cast<uint8_t>(rng() % 2 ? rng() % 12 : rng());
    if (msg.size() > 1 && rng() % 2) msg[1] = static_cast<uint8_t>(0xA0 + rng() % 0x20);
    const auto reply = h.raw(msg);
    const auto req = endat::decode_request(msg);
    if (!req) {
      REQUIRE(reply.size() == 2);
      REQUIRE(reply[1] == static_cast<uint8_t>(endat::FailureReason::MalformedRequest));
      continue;
    }
    const auto decoded = endat::decode_reply(*req, reply);
    if (!decoded) {
      REQUIRE(decoded.error() == endat::Condition::module_failure);
    } else if (req->command == endat::Command::ReadParameter) {
      REQUIRE(decoded->value() == h.bridge.encoder().word(req->mrs, 0, req->parameter));
    }
  }
}
