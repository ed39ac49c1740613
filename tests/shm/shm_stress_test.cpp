// Two processes: the writer publishes at >= 10 kHz, the reader makes 10^7 consistent reads and
// verifies every copy. Plus the control that shows the verification can fail: copies taken
// without the seqlock protocol from a flat-out writer do come out torn.
#include <catch2/catch.hpp>
#include <cstdio>
#include <cstring>
#include <set>

#include "ds1928/shm.hpp"
#include "shm_test_util.hpp"
#include "support/wait.hpp"

using namespace ds1928;
using namespace ds1928::shm;
using namespace ds1928::shm::test;

TEST_CASE("10^7 reads from another process while the writer runs at >= 10 kHz: 0 torn") {
  const auto name = unique_name("stress");
  constexpr uint32_t kAxes = 4;
  WriterProcess writer;
  writer.fifo_priority = 20;
  writer.start(name, kAxes, 50'000, 0, true);  // 20 kHz nominal
  REQUIRE(writer.running());
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  REQUIRE(
      ds1928::test::wait_until([&] { return ds1928_shm_publish_count(&reader.header()) != 0; }));

  const uint64_t count0 = ds1928_shm_publish_count(&reader.header());
  const int64_t t0 = now_ns();
  uint64_t torn = 0;
  uint64_t failed = 0;
  uint64_t changes = 0;
  uint64_t last_cycle = 0;
  uint64_t reads = 0;
  ds1928_axis_data d{};
  constexpr uint64_t kReads = 10'000'000;
  // The reads must really overlap the writes: at least 10^7 reads and the data seen changing
  // kMinChanges times. On a loaded machine the reader is descheduled now and then and sees
  // fewer changes per read, so it reads on (up to a deadline) rather than proving less.
  constexpr uint64_t kMinChanges = 1000;
  const int64_t deadline = t0 + 60'000'000'000;
  while (reads < kReads || (changes < kMinChanges && now_ns() < deadline)) {
    for (uint32_t i = 0; i < 10'000; ++i, ++reads) {
      const uint32_t axis = static_cast<uint32_t>(reads % kAxes);
      if (reader.read(axis, d)) {
        ++failed;
        continue;
      }
      if (!consistent(d, axis)) ++torn;
      if (d.cycle != last_cycle) {
        ++changes;
        last_cycle = d.cycle;
      }
    }
  }
  const int64_t elapsed = now_ns() - t0;
  const uint64_t published = ds1928_shm_publish_count(&reader.header()) - count0;
  writer.stop();
  const double rate_hz = static_cast<double>(published) * 1e9 / static_cast<double>(elapsed);
  std::printf(
      "stress: %llu reads in %.2f s, writer %.0f Hz (%llu publications), %llu data "
      "changes seen, %llu torn, %llu failed\n",
      static_cast<unsigned long long>(reads), static_cast<double>(elapsed) / 1e9, rate_hz,
      static_cast<unsigned long long>(published), static_cast<unsigned long long>(changes),
      static_cast<unsigned long long>(torn), static_cast<unsigned long long>(failed));
  CHECK(failed == 0);
  CHECK(torn == 0);
  CHECK(rate_hz >= 10'000.0);
  CHECK(changes >= kMinChanges);
}

TEST_CASE("the check value exposes copies taken without the seqlock protocol") {
  const auto name = unique_name("control");
  WriterProcess writer;
  writer.start(name, 1, 0, 0, true);  // flat out
  REQUIRE(writer.running());
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  REQUIRE(
      ds1928::test::wait_until([&] { return ds1928_shm_publish_count(&reader.header()) != 0; }));
  const ds1928_shm_axis* rec = ds1928_shm_axis_record(&reader.header(), 0);

  uint64_t raw_torn = 0;
  uint64_t raw_reads = 0;
  const int64_t deadline = now_ns() + 5'000'000'000;
  while (raw_torn < 10 && now_ns() < deadline) {
    for (int i = 0; i < 100'000; ++i, ++raw_reads) {
      uint64_t words[DS1928_AXIS_DATA_WORDS];
      for (unsigned w = 0; w < DS1928_AXIS_DATA_WORDS; ++w)
        words[w] = __atomic_load_n(&rec->u.words[w], __ATOMIC_RELAXED);
      ds1928_axis_data d;
      std::memcpy(&d, words, sizeof(d));
      if (!consistent(d, 0)) ++raw_torn;
    }
  }
  writer.stop();
  std::printf("control: %llu unprotected reads, %llu torn\n",
              static_cast<unsigned long long>(raw_reads),
              static_cast<unsigned long long>(raw_torn));
  CHECK(raw_torn > 0);
}
