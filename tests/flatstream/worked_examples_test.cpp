// The datasheet's worked example (§11.9.4.4, §11.9.4.9): messages A (7 bytes), B (2), D (9) over
// a 7-byte MTU, in all four layouts, with the corrected control bytes of the spec digest.
#include <catch2/catch.hpp>
#include <functional>
#include <map>

#include "harness.hpp"

using namespace ds1928::flatstream;
using ds1928::flatstream::test::Bytes;

namespace {

const Bytes kA{0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6, 0xA7};
const Bytes kB{0xB1, 0xB2};
const Bytes kD{0xD1, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6, 0xD7, 0xD8, 0xD9};

// Expected sequences as sent (MTU 7, unused bytes are 0 = C0).
const std::map<Layout, std::vector<Bytes>> kExpected{
    {Layout::Default,
     {{6, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
      {129, 0xA7, 0, 0, 0, 0, 0},
      {130, 0xB1, 0xB2, 0, 0, 0, 0},
      {6, 0xD1, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6},
      {131, 0xD7, 0xD8, 0xD9, 0, 0, 0}}},
    // C4 = 65: nextCBPos is set on every control byte with payload in this mode (the datasheet's
    // "7" is a misprint).
    {Layout::MultiSegmentMtu,
     {{70, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
      {193, 0xA7, 194, 0xB1, 0xB2, 65, 0xD1},
      {70, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6, 0xD7},
      {194, 0xD8, 0xD9, 0, 0, 0, 0}}},
    {Layout::LargeSegments,
     {{135, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
      {0xA7, 0, 0, 0, 0, 0, 0},
      {130, 0xB1, 0xB2, 0, 0, 0, 0},
      {137, 0xD1, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6},
      {0xD7, 0xD8, 0xD9, 0, 0, 0, 0}}},
    // The datasheet prints nextCBPos 0 (135/130/137); its rule and flow chart need 1 (199/194/201).
    {Layout::LargeMultiSegment,
     {{199, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
      {0xA7, 194, 0xB1, 0xB2, 201, 0xD1, 0xD2},
      {0xD3, 0xD4, 0xD5, 0xD6, 0xD7, 0xD8, 0xD9}}},
};

const Layout kLayouts[] = {Layout::Default, Layout::MultiSegmentMtu, Layout::LargeSegments,
                           Layout::LargeMultiSegment};

// Records every new sequence a sender puts on the bus once the direction is open.
struct Recorder {
  std::vector<Bytes> sequences;
  uint8_t last_counter = 1;  // synchronisation ends on counter 1
  void see(uint8_t reg, const MtuBytes& mtu, std::size_t n) {
    const auto r = SequenceRegister::decode(reg);
    if (r.sync_bit && r.counter != last_counter) {
      sequences.push_back(test::mtu_prefix(mtu, n));
      last_counter = r.counter;
    }
  }
};

// Plays the sending peer from raw registers: handshake as the datasheet's §4, then one sequence
// per acknowledgement. `step` takes the peer register + MTU and returns the engine's register.
using StepFn = std::function<uint8_t(uint8_t, const MtuBytes&)>;
void feed(const StepFn& step, const std::vector<Bytes>& sequences) {
  auto send_until = [&](SequenceRegister out, const MtuBytes& mtu, auto done) {
    for (int i = 0; i < 20; ++i) {
      if (done(SequenceRegister::decode(step(out.encode(), mtu)))) return;
    }
    FAIL("engine did not answer the scripted sender");
  };
  const MtuBytes idle{};
  send_until({0, false, 0, false}, idle, [](auto r) { return r.ack == 0 && !r.sync_ack; });
  send_until({1, false, 0, false}, idle, [](auto r) { return r.ack == 1 && !r.sync_ack; });
  send_until({1, true, 0, false}, idle, [](auto r) { return r.ack == 1 && r.sync_ack; });
  uint8_t counter = 1;
  for (const Bytes& s : sequences) {
    MtuBytes mtu{};
    std::copy(s.begin(), s.end(), mtu.begin());
    counter = seq_next(counter);
    send_until({counter, true, 0, false}, mtu, [&](auto r) { return r.ack == counter; });
  }
}

std::vector<Bytes> drain(auto& channel) {
  std::vector<Bytes> out;
  while (auto m = channel.take_received()) out.push_back(test::bytes_of(*m));
  return out;
}

}  // namespace

TEST_CASE("worked example: module sends the input direction in each FlatstreamMode",
          "[flatstream][example]") {
  for (Layout layout : kLayouts) {
    CAPTURE(to_string(layout));
    MasterChannel master({7, 7, Layout::Default, 1, 200});
    ModuleChannel module({7, 7, static_cast<uint8_t>(layout), 1, 0, 200});
    test::PerfectBus bus{master, module};
    REQUIRE(bus.run_until([&] {
      return master.state().receiving == ReceiverState::Open &&
             module.state().sending == SenderState::Open;
    }));
    for (const Bytes* m : {&kA, &kB, &kD}) REQUIRE_FALSE(module.submit(*m, 0));
    Recorder rec;
    for (int i = 0; i < 100; ++i) {
      bus.cycle();
      rec.see(bus.in.input_sequence, bus.in.rx, 7);
    }
    CHECK(rec.sequences == kExpected.at(layout));
    // The master's receiver reassembles them.
    CHECK(drain(master) == std::vector<Bytes>{kA, kB, kD});
    // Idle afterwards: the counter stays where the last sequence left it (C0 is never counted).
    CHECK(module.counters().sent.sequences_sent == kExpected.at(layout).size());
    int delivered = 0;
    while (auto o = module.take_outcome()) delivered += o->delivered();
    CHECK(delivered == 3);
  }
}

TEST_CASE("worked example: master sends the output direction in each layout",
          "[flatstream][example]") {
  for (Layout layout : kLayouts) {
    CAPTURE(to_string(layout));
    MasterChannel master({7, 7, layout, 1, 200});
    ModuleChannel module({7, 7, 0, 1, 0, 200});
    test::PerfectBus bus{master, module};
    REQUIRE(bus.run_until([&] { return master.state().sending == SenderState::Open; }));
    REQUIRE_FALSE(master.submit(kA, 1));
    REQUIRE_FALSE(master.submit(kB, 2));
    REQUIRE_FALSE(master.submit(kD, 3));
    Recorder rec;
    for (int i = 0; i < 100; ++i) {
      bus.cycle();
      rec.see(bus.out.output_sequence, bus.out.tx, 7);
    }
    CHECK(rec.sequences == kExpected.at(layout));
    CHECK(drain(module) == std::vector<Bytes>{kA, kB, kD});
    std::vector<uint32_t> tags;
    while (auto o = master.take_outcome()) {
      CHECK(o->delivered());
      tags.push_back(o->tag);
    }
    CHECK(tags == std::vector<uint32_t>{1, 2, 3});
  }
}

TEST_CASE("worked example: receivers reassemble the documented byte sequences",
          "[flatstream][example]") {
  // The corrected sequences, plus the variants the datasheet prints that the flow chart still
  // reads the same way: a segment ending exactly at the end of an MTU with nextCBPos 0.
  std::vector<std::pair<const char*, std::vector<Bytes>>> cases;
  for (Layout l : kLayouts) cases.emplace_back(to_string(l), kExpected.at(l));
  cases.emplace_back("multi-segment, C4 = 1",
                     std::vector<Bytes>{{70, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
                                        {193, 0xA7, 194, 0xB1, 0xB2, 1, 0xD1},
                                        {70, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6, 0xD7},
                                        {194, 0xD8, 0xD9, 0, 0, 0, 0}});
  cases.emplace_back("large+multi, C3 = 137",
                     std::vector<Bytes>{{199, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
                                        {0xA7, 194, 0xB1, 0xB2, 137, 0xD1, 0xD2},
                                        {0xD3, 0xD4, 0xD5, 0xD6, 0xD7, 0xD8, 0xD9}});
  // A trailing C0 sequence, counted by a sender that chooses to send it, is harmless.
  auto with_c0 = kExpected.at(Layout::Default);
  with_c0.push_back(Bytes(7, 0));
  cases.emplace_back("default + C0 sequence", with_c0);

  for (const auto& [name, sequences] : cases) {
    CAPTURE(name);
    MasterChannel master({7, 7, Layout::Default, 1, 200});
    feed(
        [&](uint8_t reg, const MtuBytes& mtu) {
          InputFrame f{reg, mtu};
          return master.step(f, 0).output_sequence;
        },
        sequences);
    CHECK(drain(master) == std::vector<Bytes>{kA, kB, kD});

    ModuleChannel module({7, 7, 0, 1, 0, 200});
    feed(
        [&](uint8_t reg, const MtuBytes& mtu) {
          OutputFrame f{reg, mtu};
          return module.step(f, 0).input_sequence;
        },
        sequences);
    CHECK(drain(module) == std::vector<Bytes>{kA, kB, kD});
  }
}

TEST_CASE("the datasheet's literal large+multi control bytes lose B and D (why they are corrected)",
          "[flatstream][example]") {
  // nextCBPos 0 on C1 says "the rest of the MTU after A7 is unused": B and D are skipped. This
  // documents the misprint; the engine never sends it.
  MasterChannel master({7, 7, Layout::Default, 1, 200});
  feed(
      [&](uint8_t reg, const MtuBytes& mtu) {
        return master.step({reg, mtu}, 0).output_sequence;
      },
      {{135, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6},
       {0xA7, 130, 0xB1, 0xB2, 137, 0xD1, 0xD2},
       {0xD3, 0xD4, 0xD5, 0xD6, 0xD7, 0xD8, 0xD9}});
  const auto got = drain(master);
  REQUIRE(got.size() == 1);
  CHECK(got[0] == kA);
}
