// The timed virtual CAN bus (VirtualBusOptions::bitrate > 0) on a fake clock: frames take their
// stuffed length on the wire, wait for a busy bus, go out by arbitration, reach receivers at
// their end of frame; bus load figures; the timed bus shared between two mappings and between two
// processes; the bit-rate check on opening; an allocation-free send/receive path.
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <string>
#include <vector>

#include "can/bit_budget.hpp"
#include "can/virtual_bus.hpp"
#include "support/alloc_counter.hpp"
#include "vbus_test_support.hpp"

using namespace ds1928::canio;
using namespace ds1928::canio::test;

namespace {

constexpr uint32_t kBitrate = 500'000;  // 2 µs a bit
constexpr int64_t kBit = 2'000;
constexpr int64_t kT0 = kFakeClockStart;

// The timed bus at `bitrate` on the test's fake clock.
VirtualBusOptions timed(const FakeClock& clock, uint32_t bitrate = kBitrate) {
  VirtualBusOptions o;
  o.bitrate = bitrate;
  return clock.options(o);
}

CanFrame frame(uint32_t id, uint8_t tag, uint8_t dlc = 8) {
  const uint8_t bytes[8] = {tag, 0x55, 0xAA, 3, 4, 5, 6, 7};
  return make_standard_frame(id, std::span<const uint8_t>(bytes, dlc));
}

int64_t bits_ns(const CanFrame& f) {
  return static_cast<int64_t>(frame_wire_bits(f)) * kBit;
}
// End of frame (receivers' stamp) of a frame starting at `start`: before the intermission.
int64_t eof(const CanFrame& f, int64_t start) {
  return start + bits_ns(f) - 3 * kBit;
}

}  // namespace

TEST_CASE("timed bus: wire time from the frame's real bits, stamped at end of frame",
          "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  REQUIRE(bus->timed());
  CHECK(bus->bitrate() == kBitrate);
  // SOF + 11 zero id bits + RTR, IDE, r0 + DLC 0000: 19 zeros, CRC-15 of zeros is 0: 34 zeros,
  // stuffed after every 5th (each stuff bit is a 1 that starts a run of its own) → 6 stuff bits;
  // + 13 tail bits = 53 bits = 106 µs at 500 kbit/s.
  CanFrame zero;
  CHECK(bus->wire_time_ns(zero) == 106'000);
  auto tx = port(bus), rx = port(bus);
  const CanFrame f = frame(0x181, 1);
  REQUIRE(tx->send(f).sent());
  const int64_t end = eof(f, kT0);
  CHECK(drain(*rx).empty());  // on the wire
  clock.set(end - 1);
  CHECK(drain(*rx).empty());
  clock.set(end);
  auto got = drain(*rx);
  REQUIRE(got.size() == 1);
  CHECK(got[0].rx_time_ns == end);
  CHECK(same_content(got[0], f));
  CHECK(drain(*tx).empty());  // never its own
  auto info = rx->query_interface();
  REQUIRE(info);
  CHECK(info->bitrate == kBitrate);
}

TEST_CASE("timed bus: a sender waits for a busy bus, a frame on the wire is not preempted",
          "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto a = port(bus), b = port(bus), rx = port(bus);
  const CanFrame first = frame(0x400, 1), low = frame(0x010, 2);
  REQUIRE(a->send(first).sent());
  clock.advance(10 * kBit);  // `first` is in its identifier field: it has won already
  REQUIRE(b->send(low).sent());
  const int64_t free_at = kT0 + bits_ns(first);
  clock.set(free_at + bits_ns(low));
  auto got = drain(*rx);
  REQUIRE(got.size() == 2);
  CHECK(got[0].id == 0x400);
  CHECK(got[0].rx_time_ns == eof(first, kT0));
  CHECK(got[1].id == 0x010);
  CHECK(got[1].rx_time_ns == eof(low, free_at));  // started when the bus was free
}

TEST_CASE("timed bus: frames queued on several ports go out by arbitration, lowest id first",
          "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto blocker = port(bus), p3 = port(bus), p1 = port(bus), p2 = port(bus), rx = port(bus);
  const CanFrame busy = frame(0x700, 0);
  REQUIRE(blocker->send(busy).sent());
  clock.advance(kBit);
  REQUIRE(p3->send(frame(0x300, 3)).sent());
  clock.advance(kBit);
  REQUIRE(p1->send(frame(0x100, 1)).sent());
  clock.advance(kBit);
  REQUIRE(p2->send(frame(0x200, 2)).sent());
  clock.advance(1'000'000);
  auto got = drain(*rx);
  REQUIRE(got.size() == 4);
  CHECK(got[0].id == 0x700);
  CHECK(got[1].id == 0x100);
  CHECK(got[2].id == 0x200);
  CHECK(got[3].id == 0x300);
  // One after another, never overlapping: each starts when the previous one's intermission ends.
  int64_t start = kT0;
  for (const CanFrame& f : got) {
    CHECK(f.rx_time_ns == eof(f, start));
    start += bits_ns(f);
  }
  CHECK(bus->wire_totals().bus_free_ns == start);
}

TEST_CASE("timed bus: a port's own queue is FIFO, standard beats extended with the same base",
          "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto a = port(bus), b = port(bus), c = port(bus), rx = port(bus);
  REQUIRE(c->send(frame(0x7FF, 0)).sent());  // makes the bus busy
  REQUIRE(a->send(frame(0x300, 1)).sent());  // a: 0x300 then 0x050 (one TX buffer, in order)
  REQUIRE(a->send(frame(0x050, 2)).sent());
  REQUIRE(b->send(frame(0x120, 5)).sent());
  REQUIRE(b->send(frame(0x200, 3)).sent());
  CanFrame ext = frame(0, 4);
  ext.extended = true;
  ext.id = 0x120u << 18;         // base identifier 0x120, extension bits 0
  REQUIRE(c->send(ext).sent());  // c's head after 0x7FF
  clock.advance(10'000'000);
  auto got = drain(*rx);
  REQUIRE(got.size() == 6);
  std::vector<uint8_t> order;
  for (auto& f : got) order.push_back(f.data[0]);
  // After 0x7FF the heads are a:0x300, b:0x120, c:ext 0x120 → the standard 0x120 (its RTR
  // and IDE are dominant where the extended frame sends SRR and IDE recessive); then a:0x300,
  // b:0x200, c:ext 0x120 → ext; then 0x200, then a's 0x300 and only then its 0x050.
  CHECK(order == std::vector<uint8_t>{0, 5, 4, 3, 1, 2});
}

TEST_CASE("timed bus: a full TX queue answers QueueFull without blocking, then drains",
          "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto tx = port(bus), rx = port(bus);
  int sent = 0;
  SendResult r;
  for (int i = 0; i < 100; ++i) {
    r = tx->send(frame(0x181, static_cast<uint8_t>(i)));
    if (!r.sent()) break;
    ++sent;
  }
  // The first frame went on the wire at once, 32 wait in the queue.
  CHECK(sent == 33);
  CHECK(r.status == SendStatus::QueueFull);
  CHECK(r.error_number == ENOBUFS);
  CHECK(tx->counters().tx_queue_full == 1);
  clock.advance(bits_ns(frame(0x181, 0)));  // first frame done, the second starts: one slot free
  CHECK(tx->send(frame(0x181, 200)).sent());
  clock.advance(100'000'000);
  auto got = drain(*rx);
  REQUIRE(got.size() == 34);
  for (std::size_t i = 1; i < got.size(); ++i) CHECK(got[i].rx_time_ns > got[i - 1].rx_time_ns);
}

TEST_CASE("timed bus: the timeline replays exactly when nobody looked for a while",
          "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto a = port(bus), b = port(bus), rx = port(bus);
  REQUIRE(a->send(frame(0x181, 1)).sent());  // t0
  clock.advance(1'000'000);
  REQUIRE(b->send(frame(0x281, 2)).sent());  // t0 + 1 ms: the bus was idle again
  REQUIRE(a->send(frame(0x182, 3)).sent());  // right behind: waits for 0x281, id does not matter
  clock.advance(50'000'000);
  auto got = drain(*rx);
  REQUIRE(got.size() == 3);
  CHECK(got[0].rx_time_ns == eof(got[0], kT0));
  CHECK(got[1].rx_time_ns == eof(got[1], kT0 + 1'000'000));
  CHECK(got[2].id == 0x182);
  CHECK(got[2].rx_time_ns == eof(got[2], kT0 + 1'000'000 + bits_ns(got[1])));
}

TEST_CASE("timed bus: bus load over a window and the totals", "[canio][vbus][timed]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto tx = port(bus), rx = port(bus);
  int64_t busy = 0;
  // One frame every 1 ms for 10 ms.
  for (int i = 0; i < 10; ++i) {
    const CanFrame f = frame(0x181, static_cast<uint8_t>(i));
    REQUIRE(tx->send(f).sent());
    busy += bits_ns(f);
    clock.advance(1'000'000);
  }
  const WireTotals t = bus->wire_totals();
  CHECK(t.frames == 10);
  CHECK(t.busy_ns == busy);
  const BusLoad l = bus->load(kT0, kT0 + 10'000'000);
  CHECK(l.frames == 10);
  CHECK(l.busy_ns == busy);
  CHECK(l.load == Approx(static_cast<double>(busy) / 10'000'000.0));
  // Half of the first frame's time falls into a window that starts in its middle.
  const int64_t first = bits_ns(frame(0x181, 0));
  const BusLoad part = bus->load(kT0 + first / 2, kT0 + 1'000'000);
  CHECK(part.frames == 1);
  CHECK(part.busy_ns == first - first / 2);
  CHECK(drain(*rx).size() == 10);
}

TEST_CASE("timed bus: two mappings of one shared bus arbitrate as one bus",
          "[canio][vbus][timed][process]") {
  FakeClock clock;
  const std::string name = "timed-" + std::to_string(getpid());
  (void)VirtualCanBus::remove_shared(name);
  auto one = VirtualCanBus::open_shared(name, timed(clock), true);
  REQUIRE(one);
  auto two = VirtualCanBus::open_shared(name, timed(clock));
  REQUIRE(two);
  auto blocker = port(*one), high = port(*one), low = port(*two), rx = port(*two);
  REQUIRE(blocker->send(frame(0x010, 0)).sent());
  REQUIRE(high->send(frame(0x300, 1)).sent());
  REQUIRE(low->send(frame(0x100, 2)).sent());
  clock.advance(10'000'000);
  auto got = drain(*rx);
  REQUIRE(got.size() == 3);
  CHECK(got[1].id == 0x100);
  CHECK(got[2].id == 0x300);
  CHECK(got[2].rx_time_ns == eof(got[2], kT0 + bits_ns(got[0]) + bits_ns(got[1])));
  CHECK((*one)->wire_totals().frames == 3);

  // Another bit rate (or the instant bus) under the same name is refused, naming both.
  auto other = VirtualCanBus::open_shared(name, timed(clock, 1'000'000));
  REQUIRE_FALSE(other);
  const std::string why = other.error().message();
  INFO(why);
  CHECK(why.find("500000 bit/s") != std::string::npos);
  CHECK(why.find("1000000 bit/s") != std::string::npos);
  auto instant = VirtualCanBus::open_shared(name, VirtualBusOptions{});
  REQUIRE_FALSE(instant);
  CHECK(instant.error().message().find("instant") != std::string::npos);
}

TEST_CASE("timed bus between two processes: ordered, end-of-frame stamps a frame apart",
          "[canio][vbus][timed][process]") {
  const std::string name = "timed-fork-" + std::to_string(getpid());
  (void)VirtualCanBus::remove_shared(name);
  VirtualBusOptions o;
  o.bitrate = 1'000'000;
  auto bus = VirtualCanBus::open_shared(name, o, true);
  REQUIRE(bus);
  auto me = port(*bus);
  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // The node: answers every 0x080 with 0x181 and 0x281 (first byte + 1), as a CAN-I/O node
    // answers SYNC with its two input objects.
    auto p = node_port(name, o, 0x080, frame(0x700, 0));
    std::array<CanFrame, 8> buf;
    for (int answered = 0; answered < 50;) {
      auto r = p->receive(buf, INT64_MAX);
      if (r.error) _exit(6);
      for (std::size_t i = 0; i < r.count; ++i, ++answered) {
        const auto tag = static_cast<uint8_t>(buf[i].data[0] + 1);
        if (!p->send(frame(0x281, tag)).sent() || !p->send(frame(0x181, tag)).sent()) _exit(7);
      }
    }
    _exit(0);
  }
  const int64_t deadline = deadline_in(60);
  expect_node_up(*me, 0x700, deadline);
  std::array<CanFrame, 8> buf;
  int answered = 0;
  for (int i = 0; i < 50; ++i) {
    const CanFrame sync = frame(0x080, static_cast<uint8_t>(i), 1);
    REQUIRE(me->send(sync).sent());
    std::vector<CanFrame> got;
    while (got.size() < 2) {
      auto a = me->receive(buf, deadline);
      REQUIRE(a.count > 0);
      got.insert(got.end(), buf.begin(), buf.begin() + a.count);
    }
    REQUIRE(got.size() == 2);
    // Queued 0x281 then 0x181 on one port: its FIFO, not the identifiers, decides.
    CHECK(got[0].id == 0x281);
    CHECK(got[1].id == 0x181);
    // One after the other on the bus clock: at least one frame time between the ends of frame
    // (exactly one when the node queued both before the first ended).
    CHECK(got[1].rx_time_ns - got[0].rx_time_ns >= (*bus)->wire_time_ns(got[1]));
    answered += got[0].data[0] == static_cast<uint8_t>(i + 1);
  }
  CHECK(answered == 50);
  expect_node_done(child);
  CHECK((*bus)->wire_totals().frames == 1 + 50 * 3);
}

TEST_CASE("timed bus: send and receive allocate nothing and take no lock",
          "[canio][vbus][timed][alloc]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(timed(clock));
  auto tx = port(bus), other = port(bus), rx = port(bus);
  const CanIdFilter ids[] = {{0x181, false}, {0x281, false}};
  REQUIRE_FALSE(rx->set_filters(ids));
  REQUIRE_FALSE(rx->set_error_mask(kDefaultErrorMask));
  rx->set_loss(FaultDirection::Rx, 0.05, 1);
  std::array<CanFrame, 8> buf;
  uint64_t received = 0;
  ds1928::test::HeapCounts counts;
  {
    ds1928::test::ScopedCounting counting;
    for (int i = 0; i < 10'000; ++i) {
      (void)tx->send(frame(0x181, static_cast<uint8_t>(i)));
      (void)other->send(frame(0x281, static_cast<uint8_t>(i)));
      (void)tx->send(frame(0x182, static_cast<uint8_t>(i)));
      clock.advance(1'000'000);
      received += rx->receive(buf, 0).count;
      if (i == 5000) (void)rx->inject_bus_off();
    }
    counts = counting.stop();
  }
  CHECK(received > 8000);
  CHECK(counts.allocations() == 0);
  CHECK(counts.mutex_locks == 0);
}

TEST_CASE("timed bus in virtual time: a waiting receive moves the fake clock to the next event",
          "[canio][vbus][timed]") {
  FakeClock clock;
  std::unique_ptr<VirtualCanPort> node;
  std::vector<int64_t> waits;
  VirtualBusOptions o = timed(clock);
  o.wait_until = [&](int64_t until) {
    waits.push_back(until);
    clock.set(until);
    // The peer serves its port at the new time: answers 0x080 with 0x181.
    std::array<CanFrame, 4> buf;
    const auto r = node->receive(buf, 0);
    for (std::size_t i = 0; i < r.count; ++i)
      if (buf[i].id == 0x080) REQUIRE(node->send(frame(0x181, buf[i].data[0])).sent());
  };
  auto bus = VirtualCanBus::create_local(o);
  auto master = port(bus);
  node = port(bus);
  const CanFrame sync = frame(0x080, 9, 0);
  REQUIRE(master->send(sync).sent());
  std::array<CanFrame, 4> buf;
  const auto r = master->receive(buf, kT0 + 10'000'000);
  REQUIRE(r.count == 1);
  CHECK(buf[0].id == 0x181);
  // SYNC ends, the node answers right then, its frame waits for the intermission and ends.
  const CanFrame answer = frame(0x181, 9);
  const int64_t answer_start = kT0 + bits_ns(sync);
  CHECK(buf[0].rx_time_ns == eof(answer, answer_start));
  CHECK(clock.get() == buf[0].rx_time_ns);
  REQUIRE(waits.size() >= 2);
  CHECK(waits.front() == eof(sync, kT0));
  // Nothing more on the bus: a receive waits until its deadline and returns empty.
  CHECK(master->receive(buf, clock.get() + 1'000'000).count == 0);
  CHECK(waits.back() == eof(answer, answer_start) + 1'000'000);
  node.reset();
}
