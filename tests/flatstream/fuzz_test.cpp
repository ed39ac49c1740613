// Garbage registers into both roles (built with ASan/UBSan): no crash, no stray access, and the
// counters and outputs stay within what the protocol allows. Half of the input is shaped like
// the protocol (handshake mirrored, counter +1, plausible acks) so the parser and the sender's
// error paths are reached, not only the closed state.
#include <catch2/catch.hpp>
#include <cstdlib>
#include <random>

#include "flatstream/channel.hpp"

using namespace ds1928::flatstream;

namespace {

uint64_t seed() {
  if (const char* s = std::getenv("FLATSTREAM_SEED")) return std::strtoull(s, nullptr, 0);
  return 0xF022;
}

struct Feeder {
  std::mt19937_64 rng;
  uint8_t counter = 0;
  bool sync = false;

  uint8_t byte() { return static_cast<uint8_t>(rng()); }
  // Register + MTU for the engine, given what the engine sent last.
  std::pair<uint8_t, MtuBytes> next(uint8_t engine_reg) {
    MtuBytes mtu;
    for (auto& b : mtu) b = byte();
    const auto r = SequenceRegister::decode(engine_reg);
    switch (rng() % 4) {
      case 0:
        return {byte(), mtu};
      case 1:  // follow the handshake: mirror the engine's sending nibble
        sync = (rng() % 4) != 0;
        counter = static_cast<uint8_t>(rng() % 8);
        return {SequenceRegister{counter, sync, r.counter, r.sync_bit}.encode(), mtu};
      default: {  // a "sender" moving by one, with acks near the engine's counter
        if (rng() % 8 != 0) counter = seq_next(counter);
        const uint8_t ack = (rng() % 3 == 0) ? byte() : r.counter;
        if (rng() % 3 == 0) {  // structured MTU: control bytes with plausible lengths
          for (auto& b : mtu) b = static_cast<uint8_t>((byte() & 0xC0) | (byte() % 8));
        }
        return {SequenceRegister{counter, true, ack, (rng() % 16) != 0}.encode(), mtu};
      }
    }
  }
};

template <typename Channel, typename In, typename Config>
void fuzz(Config config, uint8_t send_mtu, uint8_t recv_mtu, uint64_t s, int cycles) {
  INFO("seed " << s);
  Channel ch(config);
  Feeder f{std::mt19937_64(s)};
  uint8_t last_reg = 0;
  uint32_t next_tag = 0, expected_tag = 0;
  uint64_t now = 0;
  bool ok = true;
  for (int i = 0; i < cycles && ok; ++i) {
    auto [reg, mtu] = f.next(last_reg);
    In in{reg, mtu};
    const auto out = ch.step(in, now);
    now += (f.rng() % 8 == 0) ? f.rng() % 1000 : 100;  // time jitter, even jumps
    if constexpr (std::is_same_v<In, InputFrame>) {
      last_reg = out.output_sequence;
      for (std::size_t b = send_mtu; b < kMaxMtu; ++b) ok = ok && out.tx[b] == 0;
    } else {
      last_reg = out.input_sequence;
      for (std::size_t b = send_mtu; b < kMaxMtu; ++b) ok = ok && out.rx[b] == 0;
    }
    if (f.rng() % 16 == 0) {
      const std::size_t n = f.rng() % 600;
      std::vector<uint8_t> msg(n, 0x5A);
      const auto ec = ch.submit(msg, next_tag);
      if (!ec) ++next_tag;
      ok = ok && (n <= kMaxMessageSize || ec == make_error_code(Errc::message_too_long));
    }
    if (f.rng() % 3 == 0) {
      while (auto m = ch.take_received()) ok = ok && m->size <= kMaxMessageSize;
    }
    while (auto o = ch.take_outcome()) {
      ok = ok && o->tag == expected_tag;
      ++expected_tag;
    }
    if (f.rng() % 5000 == 0) ch.reset();
  }
  REQUIRE(ok);
  const Counters c = ch.counters();
  CHECK(expected_tag <= next_tag);
  CHECK(c.sent.messages_delivered + c.sent.messages_failed == expected_tag);
  CHECK(c.received.sequences_received <= static_cast<uint64_t>(cycles));
  CHECK(c.received.messages_received + c.received.oversized_dropped <=
        c.received.sequences_received * recv_mtu);
  CHECK(c.sent.sequences_sent + c.sent.sequences_repeated <= static_cast<uint64_t>(cycles));
  // The random input must have driven the engine beyond its closed state.
  CHECK(c.received.sequences_received > 0);
  CHECK(c.sent.ack_errors + c.sent.resyncs > 0);
}

}  // namespace

TEST_CASE("fuzz: garbage registers into the master role", "[flatstream][fuzz]") {
  std::mt19937_64 rng(seed());
  for (int round = 0; round < 24; ++round) {
    const auto out_mtu = static_cast<uint8_t>(2 + rng() % 26);
    const auto in_mtu = static_cast<uint8_t>(2 + rng() % 26);
    MasterConfig cfg{out_mtu, in_mtu, static_cast<Layout>(rng() % 4),
                     static_cast<uint8_t>(1 + rng() % 7), static_cast<uint32_t>(1 + rng() % 100)};
    fuzz<MasterChannel, InputFrame>(cfg, out_mtu, in_mtu, rng(), 20000);
  }
}

TEST_CASE("fuzz: garbage registers into the module role", "[flatstream][fuzz]") {
  std::mt19937_64 rng(seed() ^ 0x77);
  for (int round = 0; round < 24; ++round) {
    const auto out_mtu = static_cast<uint8_t>(2 + rng() % 26);
    const auto in_mtu = static_cast<uint8_t>(2 + rng() % 26);
    ModuleConfig cfg{out_mtu,
                     in_mtu,
                     static_cast<uint8_t>(rng() % 4),
                     static_cast<uint8_t>(1 + rng() % 7),
                     static_cast<uint16_t>(rng() % 3 ? 0 : rng() % 500),
                     static_cast<uint32_t>(1 + rng() % 100)};
    fuzz<ModuleChannel, OutputFrame>(cfg, in_mtu, out_mtu, rng(), 20000);
  }
}

TEST_CASE("fuzz: out-of-range configuration is clamped, not trusted", "[flatstream][fuzz]") {
  std::mt19937_64 rng(seed() ^ 0x99);
  for (int round = 0; round < 50; ++round) {
    MasterConfig mc{static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng()),
                    static_cast<Layout>(rng()), static_cast<uint8_t>(rng()), 0};
    ModuleConfig dc{static_cast<uint8_t>(rng()),  static_cast<uint8_t>(rng()),
                    static_cast<uint8_t>(rng()),  static_cast<uint8_t>(rng()),
                    static_cast<uint16_t>(rng()), 0};
    MasterChannel master(mc);
    ModuleChannel module(dc);
    InputFrame in{};
    for (int i = 0; i < 200; ++i) {
      (void)master.submit(std::vector<uint8_t>(rng() % 100, 1), 0);
      (void)module.submit(std::vector<uint8_t>(rng() % 100, 2), 0);
      in = module.step(master.step(in, static_cast<uint64_t>(i) * 100),
                       static_cast<uint64_t>(i) * 100);
      while (master.take_received()) {
      }
      while (module.take_received()) {
      }
      while (master.take_outcome()) {
      }
      while (module.take_outcome()) {
      }
    }
    SUCCEED();
  }
}
