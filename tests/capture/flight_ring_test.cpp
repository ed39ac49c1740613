// The flight recorder's ring (capture/flight_ring.hpp): exact contents, the byte bound with the
// oldest frames overwritten first, wrap-around with pad records, the time filter, and a reader
// copying out while the producer overwrites at full speed: every frame it returns is intact.
#include "capture/flight_ring.hpp"

#include <atomic>
#include <catch2/catch.hpp>
#include <cstring>
#include <thread>
#include <vector>

#include "capture/tap.hpp"

using namespace ds1928::capture;

namespace {

// Frame `seq` of length `len`: every byte derived from the sequence number, so a torn copy shows.
std::vector<uint8_t> frame_of(uint64_t seq, std::size_t len) {
  std::vector<uint8_t> f(len);
  for (std::size_t i = 0; i < len; ++i) f[i] = static_cast<uint8_t>(seq * 31 + i * 7);
  return f;
}

bool intact(const FlightFrame& f) {
  return f.bytes == frame_of(static_cast<uint64_t>(f.time_ns), f.bytes.size());
}

}  // namespace

TEST_CASE("flight ring: frames come back exactly, oldest first", "[capture][flight]") {
  FlightRing ring(64 * 1024, 1514);
  for (uint64_t s = 1; s <= 100; ++s)
    ring.record(s % 2 ? Direction::Outbound : Direction::Inbound, static_cast<int64_t>(s),
                frame_of(s, 60 + s));
  const auto frames = ring.frames_since(0);
  REQUIRE(frames.size() == 100);
  for (uint64_t s = 1; s <= 100; ++s) {
    const FlightFrame& f = frames[s - 1];
    CHECK(f.seq == s);
    CHECK(f.time_ns == static_cast<int64_t>(s));
    CHECK(f.direction == (s % 2 ? Direction::Outbound : Direction::Inbound));
    CHECK(f.bytes == frame_of(s, 60 + s));
  }
  CHECK(ring.counters().frames == 100);
  CHECK(ring.counters().overwritten == 0);
  // The time filter: frames at or after 51.
  const auto late = ring.frames_since(51);
  REQUIRE(late.size() == 50);
  CHECK(late.front().time_ns == 51);
}

TEST_CASE("flight ring: bounded in bytes, the oldest overwritten first, across wrap-arounds",
          "[capture][flight]") {
  constexpr std::size_t kBytes = 16 * 1024;
  FlightRing ring(kBytes, 1514);
  CHECK(ring.capacity_bytes() == kBytes);
  // Lengths that do not divide the ring: records end at every offset, pads of every size.
  uint64_t recorded = 0;
  for (uint64_t s = 1; s <= 5000; ++s) {
    ring.record(Direction::Inbound, static_cast<int64_t>(s), frame_of(s, 1 + (s * 37) % 300));
    ++recorded;
    if (s % 97 == 0) {
      const auto frames = ring.frames_since(0);
      REQUIRE_FALSE(frames.empty());
      // The newest frame is always there, and what is there is a contiguous run ending at it.
      CHECK(frames.back().seq == s);
      for (std::size_t i = 1; i < frames.size(); ++i) CHECK(frames[i].seq == frames[i - 1].seq + 1);
      std::size_t bytes = 0;
      for (const auto& f : frames) {
        CHECK(intact(f));
        bytes += 24 + (f.bytes.size() + 7) / 8 * 8;
      }
      CHECK(bytes <= kBytes);
      // Once full, nearly full: what is free is at most one record's words plus a pad.
      if (s >= 200) CHECK(bytes + 2 * (24 + 304) >= kBytes);
    }
  }
  const auto c = ring.counters();
  CHECK(c.frames == recorded);
  CHECK(c.frames - c.overwritten == ring.frames_since(0).size());
}

TEST_CASE("flight ring: a frame longer than max_frame is kept cut and counted",
          "[capture][flight]") {
  FlightRing ring(8192, 64);
  ring.record(Direction::Outbound, 1, frame_of(1, 100));
  const auto frames = ring.frames_since(0);
  REQUIRE(frames.size() == 1);
  CHECK(frames[0].bytes.size() == 64);
  CHECK(ring.counters().cut == 1);
  CHECK_THROWS_AS(FlightRing(1024, 1514), std::invalid_argument);
}

TEST_CASE("flight ring: a reader racing the producer gets only intact frames",
          "[capture][flight][race]") {
  FlightRing ring(8 * 1024, 512);  // small: the producer laps it thousands of times
  std::atomic<bool> stop{false};
  std::atomic<uint64_t> produced{0};
  std::thread producer([&] {
    uint64_t s = 0;
    while (!stop.load(std::memory_order_relaxed)) {
      ++s;
      ring.record(Direction::Inbound, static_cast<int64_t>(s), frame_of(s, 16 + s % 200));
      produced.store(s, std::memory_order_relaxed);
    }
  });
  uint64_t reads = 0, frames_read = 0, torn = 0, out_of_order = 0;
  while (reads < 2000 || produced.load() < 200000) {
    const auto frames = ring.frames_since(0);
    ++reads;
    frames_read += frames.size();
    for (std::size_t i = 0; i < frames.size(); ++i) {
      if (!intact(frames[i]) || frames[i].seq != static_cast<uint64_t>(frames[i].time_ns)) ++torn;
      if (i > 0 && frames[i].seq <= frames[i - 1].seq) ++out_of_order;
    }
    if (reads > 1000000) break;
  }
  stop = true;
  producer.join();
  INFO("reads " << reads << ", frames read " << frames_read << ", produced " << produced.load());
  CHECK(torn == 0);
  CHECK(out_of_order == 0);
  CHECK(ring.counters().overwritten > 0);
  // With the producer stopped the ring holds the newest frames, all intact and in order: the
  // racing reads above may have been overtaken every time (a loaded machine decides that).
  const auto settled = ring.frames_since(0);
  REQUIRE_FALSE(settled.empty());
  CHECK(settled.back().seq == produced.load());
  for (std::size_t i = 0; i < settled.size(); ++i) {
    CHECK(intact(settled[i]));
    if (i > 0) CHECK(settled[i].seq == settled[i - 1].seq + 1);
  }
}

TEST_CASE("capture tap: every frame goes to its flight ring, capture active or not",
          "[capture][flight]") {
  Tap tap("eth0", kLinkTypeEthernet, 1514, 64);
  tap.attach_flight_ring(64 * 1024);
  REQUIRE(tap.flight_ring() != nullptr);
  for (uint64_t s = 1; s <= 10; ++s) tap.record(Direction::Outbound, 0, frame_of(s, 60));
  const auto frames = tap.flight_ring()->frames_since(0);
  REQUIRE(frames.size() == 10);
  CHECK(frames[0].time_ns > 0);  // stamped now: the tap was not capturing
  CHECK(frames[9].bytes == frame_of(10, 60));
  CHECK(tap.counters().captured == 0);
}
