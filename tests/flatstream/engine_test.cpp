// Each rule of the protocol against a peer scripted register by register (datasheet §11.9.4.3,
// §11.9.4.7, §11.9.5.3-4; spec digest §4, §7, §8).
#include <catch2/catch.hpp>
#include <type_traits>

#include "harness.hpp"

using namespace ds1928::flatstream;
using test::Bytes;

// ---- Roles are types ---------------------------------------------------------------------
// A's frames feed B and B's frames feed A.
template <typename A, typename B>
concept Wirable = requires(A a, B b, uint64_t t) {
  b.step(a.step({}, t), t);
  a.step(b.step({}, t), t);
};
static_assert(Wirable<MasterChannel, ModuleChannel>);
static_assert(Wirable<ModuleChannel, MasterChannel>);
static_assert(!Wirable<MasterChannel, MasterChannel>, "two masters must not be wirable");
static_assert(!Wirable<ModuleChannel, ModuleChannel>, "two modules must not be wirable");
static_assert(!std::is_convertible_v<OutputFrame, InputFrame>);
static_assert(!std::is_convertible_v<InputFrame, OutputFrame>);

namespace {

// The module's side of the registers, played by hand against a MasterChannel.
struct ScriptedModule {
  MasterChannel& master;
  SequenceRegister in{};  // what we send: input counter/SyncBit, output ack/SyncAck
  MtuBytes rx{};
  SequenceRegister out{};  // what the master sent last
  MtuBytes tx{};
  uint64_t now_us = 0;

  void step() {
    const OutputFrame f = master.step({in.encode(), rx}, now_us);
    out = SequenceRegister::decode(f.output_sequence);
    tx = f.tx;
    now_us += 100;
  }
  // Run the output-direction handshake as the module would (mirror counter and SyncBit).
  void open_output() {
    for (int i = 0; i < 10; ++i) {
      step();
      in.ack = out.counter;
      in.sync_ack = out.sync_bit;
      if (master.state().sending == SenderState::Open) return;
    }
    FAIL("output direction did not open");
  }
};

// The master's side, played by hand against a ModuleChannel.
struct ScriptedMaster {
  ModuleChannel& module;
  SequenceRegister out{};
  MtuBytes tx{};
  SequenceRegister in{};
  MtuBytes rx{};
  uint64_t now_us = 0;
  uint64_t cycle_us = 100;

  void step() {
    const InputFrame f = module.step({out.encode(), tx}, now_us);
    in = SequenceRegister::decode(f.input_sequence);
    rx = f.rx;
    now_us += cycle_us;
  }
  void open_input() {
    for (int i = 0; i < 10; ++i) {
      step();
      out.ack = in.counter;
      out.sync_ack = in.sync_bit;
      if (module.state().sending == SenderState::Open) return;
    }
    FAIL("input direction did not open");
  }
};

Bytes pattern(std::size_t n, uint8_t base) {
  Bytes b(n);
  for (std::size_t i = 0; i < n; ++i) b[i] = static_cast<uint8_t>(base + i);
  return b;
}

}  // namespace

TEST_CASE("output synchronisation follows the datasheet's three steps", "[flatstream][sync]") {
  MasterChannel master({7, 7, Layout::Default, 1, 200});
  ScriptedModule m{master};
  m.in.ack = 5;  // not yet the mirror
  m.step();
  // 1) counter 000, SyncBit 0 — and it stays there until the module mirrors 000 / 0.
  CHECK(m.out.counter == 0);
  CHECK_FALSE(m.out.sync_bit);
  m.step();
  CHECK(m.out.counter == 0);
  m.in.ack = 0;
  m.in.sync_ack = false;
  m.step();
  // 2) counter 001, SyncBit still 0.
  CHECK(m.out.counter == 1);
  CHECK_FALSE(m.out.sync_bit);
  m.step();
  CHECK_FALSE(m.out.sync_bit);  // ack still 000
  m.in.ack = 1;
  m.step();
  // 3) SyncBit set; open only once the module answers ack 001 with SyncAck 1.
  CHECK(m.out.counter == 1);
  CHECK(m.out.sync_bit);
  CHECK(master.state().sending == SenderState::Sync2);
  m.in.sync_ack = true;
  m.step();
  CHECK(master.state().sending == SenderState::Open);
  // Nothing to send: the counter stays (no C0 sequences are counted).
  for (int i = 0; i < 5; ++i) m.step();
  CHECK(m.out.counter == 1);
}

TEST_CASE("input synchronisation: the master mirrors and takes nothing until synchronised",
          "[flatstream][sync]") {
  MasterChannel master({7, 7, Layout::Default, 1, 200});
  ScriptedModule m{master};
  m.rx = {0x83, 1, 2, 3};  // a complete message, which must not be taken while unsynchronised
  m.in.counter = 0;
  m.step();
  CHECK(m.out.ack == 0);
  CHECK_FALSE(m.out.sync_ack);
  m.in.counter = 1;
  m.step();
  CHECK(m.out.ack == 1);
  CHECK_FALSE(m.out.sync_ack);
  m.in.counter = 2;  // counter moves while SyncBit is 0: mirrored, not taken
  m.step();
  CHECK(m.out.ack == 2);
  m.in.sync_bit = true;
  m.step();
  CHECK(m.out.sync_ack);
  CHECK(master.state().receiving == ReceiverState::Open);
  CHECK_FALSE(master.take_received());
  // From now on a counter +1 is taken and acknowledged.
  m.in.counter = 3;
  m.step();
  CHECK(m.out.ack == 3);
  auto msg = master.take_received();
  REQUIRE(msg);
  CHECK(test::bytes_of(*msg) == Bytes{1, 2, 3});
}

TEST_CASE("a SyncBit set without the handshake is not acknowledged", "[flatstream][sync]") {
  MasterChannel master({7, 7, Layout::Default, 1, 200});
  ScriptedModule m{master};
  m.in = {4, true, 0, false};  // a module that believes the channel is open
  m.rx = {0x81, 9};
  for (int i = 0; i < 3; ++i) m.step();
  CHECK_FALSE(m.out.sync_ack);
  CHECK(master.state().receiving == ReceiverState::Closed);
  CHECK_FALSE(master.take_received());
}

TEST_CASE("counter jump: the receiver stops until the expected sequence is repeated",
          "[flatstream][errors]") {
  MasterChannel master({7, 7, Layout::Default, 1, 200});
  ScriptedModule m{master};
  m.in = {0, false, 0, false};
  m.step();
  m.in.counter = 1;
  m.step();
  m.in.sync_bit = true;
  m.step();
  REQUIRE(m.out.sync_ack);
  m.in.counter = 2;
  m.rx = {0x81, 0x11};
  m.step();
  REQUIRE(m.out.ack == 2);
  // Sequence 3 lost: 4 arrives.
  m.in.counter = 4;
  m.rx = {0x81, 0x44};
  m.step();
  CHECK(m.out.ack == 2);
  m.in.counter = 5;
  m.rx = {0x81, 0x55};
  m.step();
  CHECK(m.out.ack == 2);
  CHECK(master.counters().received.sequence_gaps == 1);
  // The sender repeats from 3 with the original counters.
  for (auto [c, b] : {std::pair{3, 0x33}, {4, 0x44}, {5, 0x55}}) {
    m.in.counter = static_cast<uint8_t>(c);
    m.rx = {0x81, static_cast<uint8_t>(b)};
    m.step();
    CHECK(m.out.ack == c);
  }
  std::vector<Bytes> got;
  while (auto msg = master.take_received()) got.push_back(test::bytes_of(*msg));
  CHECK(got == std::vector<Bytes>{{0x11}, {0x33}, {0x44}, {0x55}});
}

TEST_CASE("ack of an unsent sequence: close, resync, send the interrupted message again",
          "[flatstream][errors]") {
  MasterChannel master({3, 7, Layout::Default, 1, 200});
  ScriptedModule m{master};
  m.open_output();
  const Bytes msg = pattern(6, 0x10);  // 3 sequences of 2 bytes
  REQUIRE_FALSE(master.submit(msg, 7));
  m.step();
  REQUIRE(m.out.counter == 2);
  m.in.ack = 2;  // first sequence acknowledged properly
  m.step();
  REQUIRE(m.out.counter == 3);
  m.in.ack = 5;  // never sent
  m.step();
  CHECK_FALSE(m.out.sync_bit);
  CHECK(m.out.counter == 0);
  CHECK(master.counters().sent.ack_errors == 1);
  CHECK(master.counters().sent.resyncs == 1);
  CHECK_FALSE(master.take_outcome());  // not failed: its last sequence never left
  // A real module now receives the message from its first byte.
  ModuleChannel module({3, 7, 0, 1, 0, 200});
  InputFrame in{};
  for (int i = 0; i < 40; ++i) in = module.step(master.step(in, 0), 0);
  auto got = module.take_received();
  REQUIRE(got);
  CHECK(test::bytes_of(*got) == msg);
  CHECK_FALSE(module.take_received());
  auto o = master.take_outcome();
  REQUIRE(o);
  CHECK(o->tag == 7);
  CHECK(o->delivered());
  CHECK(master.counters().sent.messages_restarted == 1);
}

TEST_CASE("an ack for a sequence already acknowledged closes the channel", "[flatstream][errors]") {
  MasterChannel master({7, 7, Layout::Default, 3, 200});
  ScriptedModule m{master};
  m.open_output();
  REQUIRE_FALSE(master.submit(pattern(20, 0), 1));  // 4 sequences
  m.step();
  m.step();
  m.step();
  REQUIRE(m.out.counter == 4);
  m.in.ack = 3;
  m.step();
  m.in.ack = 2;  // backwards: 2 was acknowledged before
  m.step();
  CHECK(master.counters().sent.ack_errors == 1);
  CHECK(master.state().sending == SenderState::Sync0);
  CHECK_FALSE(m.out.sync_bit);
}

TEST_CASE("peer drops SyncAck: a message whose last sequence was sent is reported unconfirmed",
          "[flatstream][errors]") {
  MasterChannel master({7, 7, Layout::Default, 2, 200});
  ScriptedModule m{master};
  m.open_output();
  REQUIRE_FALSE(master.submit(pattern(3, 0), 1));   // one sequence
  REQUIRE_FALSE(master.submit(pattern(12, 0), 2));  // two sequences
  m.step();                                         // seq 2: message 1 complete
  m.step();                                         // seq 3: first half of message 2
  REQUIRE(m.out.counter == 3);
  m.in.sync_ack = false;  // module resets its receiver
  m.step();
  auto o = master.take_outcome();
  REQUIRE(o);
  CHECK(o->tag == 1);
  CHECK(o->result == Errc::unconfirmed);
  CHECK(o->error() == make_error_code(Errc::unconfirmed));
  CHECK_FALSE(master.take_outcome());  // message 2 will be sent again
  CHECK(master.counters().sent.messages_restarted == 1);
}

TEST_CASE("Forward: a lost sequence makes the module repeat every unacknowledged one",
          "[flatstream][forward]") {
  ModuleChannel module({7, 5, 0, 4, 0, 200});
  ScriptedMaster m{module};
  m.open_input();
  REQUIRE_FALSE(module.submit(pattern(40, 0), 1));  // 10 sequences of 4 bytes
  // Pipelined: four sequences without waiting for an ack.
  std::vector<std::pair<uint8_t, MtuBytes>> seen;
  for (int i = 0; i < 4; ++i) {
    m.step();
    seen.emplace_back(m.in.counter, m.rx);
  }
  CHECK(seen[0].first == 2);
  CHECK(seen[3].first == 5);
  // The master took 2 and acknowledged it, then lost 3 and stopped.
  m.out.ack = 2;
  for (int i = 0; i < 4; ++i) m.step();
  // Window (4) full: the module waits, then repeats 3, 4, 5, 6 with the original bytes.
  std::vector<std::pair<uint8_t, MtuBytes>> repeats;
  for (int i = 0; i < 20 && repeats.size() < 4; ++i) {
    const uint8_t before = m.in.counter;
    m.step();
    if (m.in.counter != before) repeats.emplace_back(m.in.counter, m.rx);
  }
  REQUIRE(repeats.size() == 4);
  CHECK(repeats[0].first == 3);
  CHECK(repeats[0].second == seen[1].second);
  CHECK(repeats[2].first == 5);
  CHECK(repeats[2].second == seen[3].second);
  CHECK(module.counters().sent.sequences_repeated >= 4);
}

TEST_CASE("Forward: a lost ack is covered by the next one, nothing is repeated",
          "[flatstream][forward]") {
  ModuleChannel module({7, 5, 0, 7, 0, 200});
  ScriptedMaster m{module};
  m.open_input();
  REQUIRE_FALSE(module.submit(pattern(12, 0), 1));  // 3 sequences
  m.step();
  m.step();
  m.step();
  REQUIRE(m.in.counter == 4);
  m.out.ack = 4;  // acks for 2 and 3 never arrived: cumulative
  m.step();
  auto o = module.take_outcome();
  REQUIRE(o);
  CHECK(o->delivered());
  for (int i = 0; i < 20; ++i) m.step();
  CHECK(module.counters().sent.sequences_repeated == 0);
  CHECK(module.counters().sent.ack_errors == 0);
}

TEST_CASE("per-sequence timeout reports the message in progress failed", "[flatstream][errors]") {
  MasterChannel master({7, 7, Layout::Default, 1, 30});
  ScriptedModule m{master};
  m.open_output();
  REQUIRE_FALSE(master.submit(pattern(20, 0), 9));
  int cycles = 0;
  std::optional<SendOutcome> o;
  while (!o && cycles < 100) {
    m.step();  // the module never acknowledges
    ++cycles;
    o = master.take_outcome();
  }
  REQUIRE(o);
  CHECK(o->tag == 9);
  CHECK(o->result == Errc::timeout);
  CHECK(cycles >= 30);
  CHECK(cycles <= 33);
  CHECK(master.counters().sent.timeouts == 1);
  CHECK(master.state().sending == SenderState::Sync0);
}

TEST_CASE("a peer that never synchronises still yields an outcome", "[flatstream][errors]") {
  MasterChannel master({7, 7, Layout::Default, 1, 20});
  ScriptedModule m{master};
  m.in.ack = 3;  // never mirrors
  REQUIRE_FALSE(master.submit(Bytes{1}, 4));
  std::optional<SendOutcome> o;
  for (int i = 0; i < 30 && !o; ++i) {
    m.step();
    o = master.take_outcome();
  }
  REQUIRE(o);
  CHECK(o->result == Errc::not_synchronised);
}

TEST_CASE("ForwardDelay spaces the module's sequences and acknowledgements",
          "[flatstream][forward]") {
  ModuleChannel module({7, 5, 0, 7, 350, 200});
  ScriptedMaster m{module};
  m.cycle_us = 100;
  m.open_input();
  REQUIRE_FALSE(module.submit(pattern(40, 0), 1));
  std::vector<uint64_t> sent_at;
  uint8_t last = m.in.counter;
  for (int i = 0; i < 30; ++i) {
    const uint64_t t = m.now_us;
    m.step();
    m.out.ack = m.in.counter;
    if (m.in.counter != last) sent_at.push_back(t);
    last = m.in.counter;
  }
  REQUIRE(sent_at.size() >= 3);
  for (std::size_t i = 1; i < sent_at.size(); ++i) CHECK(sent_at[i] - sent_at[i - 1] >= 350);
}

TEST_CASE("a full receive queue holds the sequence back instead of losing it",
          "[flatstream][receiver]") {
  MasterChannel master({7, 7, Layout::Default, 1, 1000});
  ModuleChannel module({7, 7, 1, 7, 0, 1000});
  test::PerfectBus bus{master, module};
  const std::size_t n = kQueueDepth + 10;
  std::size_t submitted = 0, received = 0;
  for (int i = 0; i < 400; ++i) {
    if (submitted < n && !module.submit(Bytes{static_cast<uint8_t>(submitted)}, 0)) ++submitted;
    while (module.take_outcome()) {
    }
    bus.cycle();
  }
  CHECK(master.counters().received.stalled_cycles > 0);
  Message msg;
  while (received < n) {
    while (master.take_received(msg)) {
      CHECK(msg.size == 1);
      CHECK(msg.bytes[0] == static_cast<uint8_t>(received));
      ++received;
    }
    bus.cycle();
    if (bus.now_us > 1000000) break;
  }
  CHECK(received == n);
}

TEST_CASE("submit rejects oversized messages and a full queue", "[flatstream][api]") {
  MasterChannel master({7, 7, Layout::Default, 1, 200});
  const Bytes big(kMaxMessageSize + 1, 0);
  CHECK(master.submit(big, 0) == make_error_code(Errc::message_too_long));
  CHECK_FALSE(master.submit(Bytes(kMaxMessageSize, 0), 0));
  for (std::size_t i = 1; i < kQueueDepth; ++i) CHECK_FALSE(master.submit(Bytes{1}, 0));
  CHECK(master.submit(Bytes{1}, 0) == make_error_code(Errc::queue_full));
  master.reset();  // everything queued is reported
  std::size_t outcomes = 0;
  while (auto o = master.take_outcome()) {
    CHECK(o->result == Errc::channel_reset);
    ++outcomes;
  }
  CHECK(outcomes == kQueueDepth);
  CHECK_FALSE(master.submit(Bytes{1}, 0));
  CHECK(std::string(make_error_code(Errc::queue_full).category().name()) == "flatstream");
}

TEST_CASE("configuration validation names the wrong field", "[flatstream][api]") {
  CHECK_FALSE(validate(MasterConfig{}));
  CHECK_FALSE(validate(ModuleConfig{}));
  CHECK(validate(MasterConfig{1, 7, Layout::Default, 1, 200}) ==
        make_error_code(Errc::invalid_mtu));
  CHECK(validate(MasterConfig{7, 28, Layout::Default, 1, 200}) ==
        make_error_code(Errc::invalid_mtu));
  CHECK(validate(MasterConfig{7, 7, Layout::Default, 8, 200}) ==
        make_error_code(Errc::invalid_forward));
  CHECK(validate(MasterConfig{7, 7, Layout::Default, 1, 0}) ==
        make_error_code(Errc::invalid_timeout));
  CHECK(validate(ModuleConfig{7, 7, 4, 1, 0, 200}) == make_error_code(Errc::invalid_layout));
  CHECK(validate(ModuleConfig{7, 7, 0, 0, 0, 200}) == make_error_code(Errc::invalid_forward));
}

TEST_CASE("every MTU 2..27 carries messages of 0..512 bytes in every layout", "[flatstream][api]") {
  for (uint8_t mtu = 2; mtu <= 27; ++mtu) {
    for (uint8_t mode = 0; mode < 4; ++mode) {
      CAPTURE(int(mtu), int(mode));
      MasterChannel master({mtu, mtu, static_cast<Layout>(mode), 7, 5000});
      ModuleChannel module({mtu, mtu, mode, 7, 0, 5000});
      test::PerfectBus bus{master, module};
      const std::vector<std::size_t> sizes{0, 1, mtu - 1u, mtu, 62, 63, 64, 127, 512};
      for (std::size_t i = 0; i < sizes.size(); ++i) {
        REQUIRE_FALSE(master.submit(pattern(sizes[i], static_cast<uint8_t>(i)), 0));
        REQUIRE_FALSE(module.submit(pattern(sizes[i], static_cast<uint8_t>(i + 100)), 0));
      }
      std::vector<Bytes> at_module, at_master;
      for (int c = 0;
           c < 4000 && (at_module.size() < sizes.size() || at_master.size() < sizes.size()); ++c) {
        bus.cycle();
        while (auto m = module.take_received()) at_module.push_back(test::bytes_of(*m));
        while (auto m = master.take_received()) at_master.push_back(test::bytes_of(*m));
      }
      REQUIRE(at_module.size() == sizes.size());
      REQUIRE(at_master.size() == sizes.size());
      for (std::size_t i = 0; i < sizes.size(); ++i) {
        CHECK(at_module[i] == pattern(sizes[i], static_cast<uint8_t>(i)));
        CHECK(at_master[i] == pattern(sizes[i], static_cast<uint8_t>(i + 100)));
      }
    }
  }
}
