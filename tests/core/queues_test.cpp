// The lock-free hand-overs between the cycle thread and the normal thread: SpscQueue (with the
// peek/drop used to leave a request queued) and TripleBuffer, single-threaded and under two
// threads hammering them.
#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <thread>

#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"

using namespace ds1928;

TEST_CASE("SpscQueue front() leaves the element queued until drop_front()", "[core][queue]") {
  SpscQueue<int, 4> q;
  CHECK(q.front() == nullptr);
  REQUIRE(q.try_push(1));
  REQUIRE(q.try_push(2));
  REQUIRE(q.front() != nullptr);
  CHECK(*q.front() == 1);
  CHECK(*q.front() == 1);  // peeking twice takes nothing
  q.drop_front();
  CHECK(*q.front() == 2);
  REQUIRE(q.try_push(3));
  REQUIRE(q.try_push(4));
  REQUIRE(q.try_push(5));
  CHECK_FALSE(q.try_push(6));  // full: 2 3 4 5
  CHECK(q.try_pop() == 2);
  CHECK(*q.front() == 3);
  q.drop_front();
  q.drop_front();
  CHECK(q.try_pop() == 5);
  CHECK(q.front() == nullptr);
  CHECK(q.empty());
}

TEST_CASE("SpscQueue across two threads: every element once, in order", "[core][queue]") {
  SpscQueue<uint32_t, 64> q;
  constexpr uint32_t kCount = 200'000;
  std::thread producer([&] {
    // A full queue yields the core: on one busy core a spinning side would burn its time slice.
    for (uint32_t i = 0; i < kCount;)
      if (q.try_push(i))
        ++i;
      else
        std::this_thread::yield();
  });
  uint32_t expected = 0;
  bool in_order = true;
  while (expected < kCount) {
    // Alternate both ways of consuming.
    if (expected % 2 == 0) {
      if (uint32_t* v = q.front()) {
        in_order &= *v == expected;
        q.drop_front();
        ++expected;
        continue;
      }
    } else if (auto v = q.try_pop()) {
      in_order &= *v == expected;
      ++expected;
      continue;
    }
    std::this_thread::yield();
  }
  producer.join();
  CHECK(in_order);
  CHECK(q.empty());
}

namespace {
struct Big {
  std::array<uint64_t, 64> words{};  // all equal in a value that was published whole
};
}  // namespace

TEST_CASE("TripleBuffer: the reader sees the latest value, or the one before", "[core][triple]") {
  TripleBuffer<int> tb(7);
  CHECK(tb.read() == 7);  // nothing published: the initial value
  tb.back() = 1;
  tb.publish();
  CHECK(tb.read() == 1);
  CHECK(tb.read() == 1);  // nothing new: the same value again
  tb.back() = 2;
  tb.publish();
  tb.back() = 3;
  tb.publish();
  CHECK(tb.read() == 3);  // the latest, 2 was overtaken
  tb.back() = 4;          // filled, not published
  CHECK(tb.read() == 3);
}

TEST_CASE("TripleBuffer across two threads: never a torn value, never going back",
          "[core][triple]") {
  TripleBuffer<Big> tb;
  std::atomic<bool> stop{false};
  constexpr uint64_t kValues = 300'000;
  // The threads run freely between checkpoints; at each one the writer waits until the reader
  // has seen that value. So the reader sees at least kValues / kCheckpoint distinct values
  // however the scheduler runs the two threads (both may share one core).
  constexpr uint64_t kCheckpoint = 1'000;
  std::atomic<uint64_t> seen{0};
  std::thread writer([&] {
    for (uint64_t v = 1; v <= kValues; ++v) {
      Big& b = tb.back();
      for (auto& w : b.words) w = v;
      tb.publish();
      if (v % kCheckpoint == 0) {
        for (uint64_t s = seen.load(std::memory_order_acquire); s < v;
             s = seen.load(std::memory_order_acquire))
          seen.wait(s, std::memory_order_acquire);
      }
    }
    stop.store(true, std::memory_order_release);
  });
  uint64_t torn = 0, backwards = 0, reads = 0, last = 0, distinct = 0;
  for (;;) {
    const bool finished = stop.load(std::memory_order_acquire);
    const Big& b = tb.read();
    const uint64_t v = b.words[0];
    for (uint64_t w : b.words) torn += w != v;
    backwards += v < last;
    if (v != last) {
      ++distinct;
      seen.store(v, std::memory_order_release);
      seen.notify_one();
    }
    last = v;
    ++reads;
    if (finished) break;
  }
  writer.join();
  INFO(reads << " reads, " << distinct << " distinct values");
  CHECK(torn == 0);
  CHECK(backwards == 0);
  CHECK(last == kValues);  // the last value published is the one read at the end
  CHECK(distinct >= kValues / kCheckpoint);
}
