// The time base in the shared memory: the header's timeline and measured publication offset,
// each axis' acquisition-to-publication time, ds1928_shm_next_publication(), and a reader built
// against the header before the time base existed.
#include <catch2/catch.hpp>
#include <vector>

#include "core/clock.hpp"
#include "ds1928/shm.hpp"
#include "old_reader.h"
#include "shm_test_util.hpp"
#include "support/alloc_counter.hpp"

using namespace ds1928;
using namespace ds1928::shm;
using namespace ds1928::shm::test;

namespace {

constexpr int64_t kPeriod = 1'000'000;

// Cycle `index` of a timeline whose cycle started `ago_ns` before now: the publication's offset
// in the cycle is at least ago_ns, whatever the scheduling.
CycleContext context_for(uint64_t index, int64_t ago_ns, int64_t& t0, const TimebaseStatus* tb) {
  const int64_t start = rt::now_ns() - ago_ns;
  t0 = start - static_cast<int64_t>(index) * kPeriod;
  return CycleContext{index, start, start, t0, tb};
}

}  // namespace

TEST_CASE("the header carries the time base: timeline, publication offset, acquisition time") {
  const auto name = unique_name("timebase");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 2, kPeriod));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  const ds1928_shm_header& h = reader.header();
  CHECK(ds1928_shm_has_timebase(&h));
  int64_t at = 0;
  uint64_t cycle = 0;
  // Before the first cycle there is no timeline yet.
  CHECK(ds1928_shm_next_publication(&h, rt::now_ns(), 1, &at, &cycle) == -EAGAIN);

  TimebaseStatus tb;
  tb.kind = TimebaseKind::Tai;
  tb.tai_offset_ns = 37'000'000'000 + 123;
  tb.steps = 2;
  tb.last_step_ns = -250'000;
  std::vector<AxisStatus> st(2);
  int64_t t0 = 0;
  // 300 µs into the cycle, the positions acquired 50 µs before that.
  for (uint64_t c = 1; c <= 63; ++c) {
    for (uint32_t a = 0; a < 2; ++a) st[a] = status_for(c, a);
    const CycleContext ctx = context_for(c, 300'000, t0, &tb);
    st[0].sample.pos_time_ns = ctx.start_ns + 250'000;
    st[1].sample.fresh = false;
    pub.publish(ctx, st);
  }
  CHECK(h.timebase_t0_ns != 0);
  CHECK(h.publish_offset_p99_ns == 0);  // not measured before 64 publications
  const auto* rec0 = ds1928_shm_axis_record(&h, 0);
  const auto* rec1 = ds1928_shm_axis_record(&h, 1);
  CHECK(rec0->acq_to_publish_ns >= 50'000);
  CHECK(rec1->acq_to_publish_ns == 0);  // no fresh input: nothing measured

  for (uint32_t a = 0; a < 2; ++a) st[a] = status_for(64, a);
  const CycleContext ctx = context_for(64, 300'000, t0, &tb);
  st[0].sample.pos_time_ns = ctx.start_ns + 250'000;
  st[1].sample.fresh = false;
  pub.publish(ctx, st);

  CHECK(h.timebase_t0_ns == t0);
  CHECK(h.cycle_period_ns == static_cast<uint64_t>(kPeriod));
  CHECK(h.timebase_kind == DS1928_TIMEBASE_TAI);
  CHECK(h.timebase_tai_offset_ns == tb.tai_offset_ns);
  CHECK(h.timebase_steps == 2);
  CHECK(h.timebase_last_step_ns == -250'000);
  CHECK(h.publish_offset_p50_ns >= 300'000);
  CHECK(h.publish_offset_p99_ns >= h.publish_offset_p50_ns);
  CHECK(h.publish_offset_max_ns >= h.publish_offset_p99_ns);
  CHECK(rec0->acq_to_publish_max_ns >= rec0->acq_to_publish_ns);
  CHECK(rec0->acq_to_publish_max_ns >= 50'000);
  CHECK(rec1->acq_to_publish_max_ns == 0);

  // The next publication of a multiple of 4 after cycle 64's start: cycle 68's, at its start
  // plus the offset p99; from there, cycle 72's.
  const int64_t p99 = h.publish_offset_p99_ns;
  REQUIRE(ds1928_shm_next_publication(&h, t0 + 64 * kPeriod + p99, 4, &at, &cycle) == 0);
  CHECK(cycle == 68);
  CHECK(at == t0 + 68 * kPeriod + p99);
  REQUIRE(ds1928_shm_next_publication(&h, at, 4, &at, &cycle) == 0);
  CHECK(cycle == 72);
  // Just before cycle 65's publication: that one (every = 0 counts as 1).
  REQUIRE(ds1928_shm_next_publication(&h, t0 + 65 * kPeriod + p99 - 1, 0, &at, &cycle) == 0);
  CHECK(cycle == 65);
  // Before the timeline began: cycle 0.
  REQUIRE(ds1928_shm_next_publication(&h, t0 - 5 * kPeriod, 3, &at, &cycle) == 0);
  CHECK(cycle == 0);
  CHECK(at == t0 + p99);
}

TEST_CASE("the measurement window closes after 1024 publications and starts again") {
  const auto name = unique_name("window");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 1, kPeriod));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  const ds1928_shm_header& h = reader.header();
  std::vector<AxisStatus> st(1);
  int64_t t0 = 0;
  uint64_t c = 1;
  // A first window at 600 µs, a second at 100 µs: the second's figures replace the first's.
  for (; c <= Publisher::kTimebaseWindow; ++c) {
    st[0] = status_for(c, 0);
    pub.publish(context_for(c, 600'000, t0, nullptr), st);
  }
  const uint32_t first_p50 = h.publish_offset_p50_ns;
  CHECK(first_p50 >= 600'000);
  for (; c <= 2 * Publisher::kTimebaseWindow - 1; ++c) {
    st[0] = status_for(c, 0);
    pub.publish(context_for(c, 100'000, t0, nullptr), st);
  }
  CHECK(h.publish_offset_p50_ns == first_p50);  // the window is still open
  st[0] = status_for(c, 0);
  pub.publish(context_for(c, 100'000, t0, nullptr), st);
  CHECK(h.publish_offset_p50_ns >= 100'000);
  CHECK(h.publish_offset_p50_ns < first_p50);
  CHECK(h.timebase_kind == DS1928_TIMEBASE_MONOTONIC);
}

TEST_CASE("publishing the time base allocates nothing and takes no mutex") {
  const auto name = unique_name("tb-rt");
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 4, kPeriod));
  std::vector<AxisStatus> st(4);
  TimebaseStatus tb;
  int64_t t0 = 0;
  ds1928::test::HeapCounts counts;
  {
    ds1928::test::ScopedCounting scope;
    for (uint64_t c = 1; c <= 5'000; ++c) {  // several windows
      for (uint32_t a = 0; a < 4; ++a) st[a] = status_for(c, a);
      pub.publish(context_for(c, 10'000, t0, &tb), st);
    }
    counts = scope.stop();
  }
  CHECK(counts.allocations() == 0);
  CHECK(counts.mutex_locks == 0);
  CHECK(pub.wake_calls() == 0);
}

TEST_CASE("a reader built against the header before the time base reads the new daemon") {
  const auto name = unique_name("oldreader");
  Publisher pub;
  // With the additional-information channels too: their names table and record words are
  // beyond what the old header knows.
  std::vector<InfoNames> names(3, InfoNames{"temperature1", "", "", "position2_word1"});
  REQUIRE_FALSE(pub.open(config_for(name), 3, kPeriod, names));
  std::vector<AxisStatus> st(3);
  TimebaseStatus tb;
  int64_t t0 = 0;
  for (uint64_t c = 1; c <= 100; ++c) {
    for (uint32_t a = 0; a < 3; ++a) {
      st[a] = status_for(c, a);
      st[a].info.configured = 0b1001;
      update_axis_info(st[a].info, 0b1001, {0xFFFF, 0, 0, 0x1234}, rt::now_ns());
    }
    pub.publish(context_for(c, 20'000, t0, &tb), st);
  }
  for (uint32_t a = 0; a < 3; ++a) {
    old_reader_result r{};
    REQUIRE(old_reader_read(name.c_str(), a, &r) == 0);
    const AxisStatus want = status_for(100, a);
    CHECK(r.cycle == 100);
    CHECK(r.position_raw == want.sample.position_raw);
    CHECK(r.periods == want.sample.periods);
    CHECK(r.check_ok);
    CHECK(r.validity == DS1928_AXIS_VALID);
    CHECK(r.last_cycle == 100);
    CHECK(r.alive);
    CHECK(r.can_wait);
  }
  old_reader_result r{};
  CHECK(old_reader_read(name.c_str(), 3, &r) == -EINVAL);
}
