// Proof that the cycle thread allocates nothing and takes no mutex in steady state, and the
// self-tests that show the counter would notice if it did.
#include <pthread.h>

#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <thread>

#include "core/axis_sample.hpp"
#include "core/cycle_engine.hpp"
#include "core/spsc_queue.hpp"
#include "support/alloc_counter.hpp"
#include "support/wait.hpp"

using namespace ds1928;
namespace t = ds1928::test;

namespace {
// Keeps the optimiser from removing a new/delete pair.
void* volatile g_sink = nullptr;
}  // namespace

TEST_CASE("counter sees operator new, malloc from libc and mutex locks", "[alloc_counter]") {
  t::ScopedCounting scope;
  int* p = new int(7);
  g_sink = p;
  delete p;
  char* s = strdup("ds1928");  // malloc called from inside glibc
  g_sink = s;
  free(s);
  std::mutex m;
  m.lock();
  m.unlock();
  const auto c = scope.stop();
  if (t::counts_new_separately()) {
    CHECK(c.new_calls == 1);
    CHECK(c.delete_calls == 1);
    CHECK(c.malloc_calls == 1);
    CHECK(c.free_calls == 1);
  } else {
    WARN("sanitizer build: operator new is counted as malloc");
    CHECK(c.allocations() == 2);
    CHECK(c.deallocations() == 2);
  }
  if (t::counts_mutexes())
    CHECK(c.mutex_locks == 1);
  else
    WARN("TSan build: mutex locks are not counted (TSan intercepts them); check skipped");
  CHECK(c.first_size == sizeof(int));
  CHECK_FALSE(t::counting());
  // Stopped: nothing more is counted.
  g_sink = malloc(16);
  free(g_sink);
  CHECK(t::current_counts().allocations() == c.allocations());
}

TEST_CASE("counter ignores other threads", "[alloc_counter]") {
  std::atomic<int> step{0};
  std::thread other([&] {
    while (step.load() != 1) std::this_thread::yield();
    for (int i = 0; i < 100; ++i) {
      auto* v = new std::array<int, 64>{};
      g_sink = v;
      delete v;
    }
    step.store(2);
  });
  t::begin_counting();
  step.store(1);
  while (step.load() != 2) std::this_thread::yield();
  const auto c = t::end_counting();
  other.join();
  CHECK(c.allocations() == 0);
  CHECK(c.deallocations() == 0);
}

namespace {

constexpr int kAxes = 4;

// The shape of the daemon's cycle: per axis, stage outputs, read an image, decode it, hand the
// sample to the normal thread through an SPSC queue; plus reading back a command from the
// normal thread. The image is synthesised so the test needs no bus.
struct RepresentativeTask : CycleTask {
  RepresentativeTask(uint64_t warmup, uint64_t counted) : warmup_(warmup), counted_(counted) {}

  void run_cycle(const CycleContext& ctx) noexcept override {
    if (executed_ == warmup_) t::begin_counting();

    for (int a = 0; a < kAxes; ++a) {
      AxisIo& io = io_[a];
      io.outputs.output_sequence = static_cast<uint8_t>(ctx.index);
      io.outputs.tx_bytes[0] = static_cast<uint8_t>(a);
      const uint64_t pos = (ctx.index * 8192u + static_cast<uint64_t>(a) * 65536u) & ~7ull;
      io.inputs.position_hw = static_cast<uint32_t>(pos >> 32);
      io.inputs.position_lw = static_cast<uint32_t>(pos);
      io.inputs.pos_time_us = static_cast<uint32_t>(ctx.start_ns / 1000);
      io.inputs.pos_cycle = static_cast<int8_t>(ctx.index / 2);
      io.inputs_fresh = true;
      io.rx_time_ns = ctx.woke_ns;
      NetTimeRef ref{static_cast<uint64_t>(ctx.start_ns / 1000), ctx.start_ns, true};
      const AxisSample sample = decode_axis(io, AxisDecodeParams{}, ref, decode_[a]);
      if (!samples_.try_push(sample)) dropped_.fetch_add(1, std::memory_order_relaxed);
    }
    while (auto cmd = commands_.try_pop()) io_[*cmd % kAxes].outputs.ack_error_info = 1;
    if (allocate_every_ != 0 && executed_ % allocate_every_ == 0) {
      g_sink = new int(static_cast<int>(ctx.index));  // the fault the proof must catch
      delete static_cast<int*>(g_sink);
    }

    ++executed_;
    if (executed_ == warmup_ + counted_) {
      result_ = t::end_counting();
      done_.store(true, std::memory_order_release);
    }
  }

  const uint64_t warmup_;
  const uint64_t counted_;
  uint64_t executed_ = 0;
  uint64_t allocate_every_ = 0;
  std::array<AxisIo, kAxes> io_{};
  std::array<AxisDecodeState, kAxes> decode_{};
  SpscQueue<AxisSample, 1024> samples_;
  SpscQueue<uint32_t, 64> commands_;
  std::atomic<uint64_t> dropped_{0};
  t::HeapCounts result_{};
  std::atomic<bool> done_{false};
};

// Runs the engine until the task has counted its cycles, while this thread plays the normal
// side: drains samples, feeds commands, reads statistics and asks for a reset.
t::HeapCounts run_and_count(RepresentativeTask& task, uint32_t period_us,
                            CycleStatsSnapshot& final_stats) {
  CycleConfig config;
  config.period_us = period_us;
  config.rt_priority = 80;
  auto engine = std::make_unique<CycleEngine>(config, task);
  auto r = engine->start();
  REQUIRE_FALSE(r.error);
  uint64_t popped = 0;
  uint32_t sent = 0;
  bool reset_sent = false;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!task.done_.load(std::memory_order_acquire) && std::chrono::steady_clock::now() < until) {
    while (task.samples_.try_pop()) ++popped;
    if (task.commands_.try_push(sent)) ++sent;
    (void)engine->stats_snapshot();
    if (!reset_sent && engine->cycle_count() > task.warmup_ + task.counted_ / 2) {
      engine->request_stats_reset();  // applied on the cycle thread inside the counted window
      reset_sent = true;
    }
    // Next round after 5 more cycles: the consumer keeps pace with the cycle, not the clock.
    const uint64_t next = engine->cycle_count() + 5;
    (void)t::wait_until([&] {
      return task.done_.load(std::memory_order_acquire) || engine->cycle_count() >= next;
    });
  }
  engine->stop();
  final_stats = engine->stats_snapshot();
  REQUIRE(task.done_.load());
  CHECK(popped > 0);
  CHECK(final_stats.reset_generation == (reset_sent ? 1u : 0u));
  return task.result_;
}

}  // namespace

TEST_CASE("cycle thread: zero allocations and no mutex over 100 000 steady cycles",
          "[cycle_engine][alloc]") {
  auto task = std::make_unique<RepresentativeTask>(2000, 100'000);
  CycleStatsSnapshot stats;
  const auto c = run_and_count(*task, 100, stats);
  INFO("new " << c.new_calls << ", malloc " << c.malloc_calls << ", delete " << c.delete_calls
              << ", free " << c.free_calls << ", mutex " << c.mutex_locks
              << ", first allocation size " << c.first_size);
  INFO("wake p99 " << stats.wake_latency.p99_ns << " ns, overruns " << stats.overruns);
  CHECK(c.allocations() == 0);
  CHECK(c.deallocations() == 0);
  CHECK(c.mutex_locks == 0);
  if (!t::counts_mutexes()) WARN("TSan build: mutex locks are not counted; that check is void");
  CHECK(task->executed_ >= 102'000);
}

TEST_CASE("the allocation proof fails when the cycle allocates", "[cycle_engine][alloc]") {
  auto task = std::make_unique<RepresentativeTask>(200, 3000);
  task->allocate_every_ = 500;
  CycleStatsSnapshot stats;
  const auto c = run_and_count(*task, 100, stats);
  // Cycles 500, 1000, ..., 3000 of the counted window [200, 3200).
  if (t::counts_new_separately()) {
    CHECK(c.new_calls == 6);
    CHECK(c.delete_calls == 6);
  } else {
    WARN("sanitizer build: operator new is counted as malloc");
    CHECK(c.allocations() == 6);
    CHECK(c.deallocations() == 6);
  }
}
