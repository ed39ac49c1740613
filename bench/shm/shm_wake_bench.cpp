// What a publication costs the cycle thread with 0, 1 and 16 readers asleep, and how late a
// sleeping reader wakes, for the daemon's design (the wake-up thread makes the FUTEX_WAKE) next
// to the former one (the cycle thread made it itself, inline after the records), in the same run,
// rounds alternating.
//
// Set-up like the daemon: the "cycle thread" is SCHED_FIFO PRIO pinned to CPU, publishing every
// PERIOD µs on an absolute timeline; the wake-up thread runs at PRIO-1 on the same CPU; readers
// are SCHED_FIFO PRIO-10 threads, not pinned, each in ds1928_shm_wait (factor 1). The former
// design is replayed exactly on a private copy of the layout: the same seqlock records, the
// futex word, the slot scan and one FUTEX_WAKE_BITSET when a slot has waiters, all on the cycle
// thread. Publication cost = the publish call on the cycle thread (TSC, serialised); wake-up
// latency = reader back from ds1928_shm_wait − the publication's CLOCK_MONOTONIC stamp.
//
//   shm_wake_bench [--axes 4] [--period-us 500] [--publications 4000] [--rounds 3]
//                  [--cpu 1] [--priority 80]
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <x86intrin.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "ds1928/shm.hpp"
#include "shm/publisher.hpp"

using namespace ds1928;

namespace {

inline uint64_t tsc_begin() {
  _mm_lfence();
  return __rdtsc();
}
inline uint64_t tsc_end() {
  unsigned aux;
  const uint64_t t = __rdtscp(&aux);
  _mm_lfence();
  return t;
}
double tsc_per_ns() {
  const int64_t n0 = ds1928_shm_now_ns();
  const uint64_t t0 = __rdtsc();
  usleep(200'000);
  return static_cast<double>(__rdtsc() - t0) / static_cast<double>(ds1928_shm_now_ns() - n0);
}

struct Quantiles {
  double p50 = 0, p99 = 0, max = 0;
  size_t n = 0;
};
Quantiles quantiles(std::vector<double> v) {
  Quantiles q;
  q.n = v.size();
  if (v.empty()) return q;
  std::sort(v.begin(), v.end());
  auto at = [&](double p) { return v[static_cast<size_t>(p * static_cast<double>(v.size() - 1))]; };
  q.p50 = at(0.5);
  q.p99 = at(0.99);
  q.max = v.back();
  return q;
}

void sleep_until(int64_t t) {
  timespec ts{static_cast<time_t>(t / 1'000'000'000), static_cast<long>(t % 1'000'000'000)};
  clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

void set_fifo(int prio) {
  sched_param sp{};
  sp.sched_priority = prio;
  pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
}

shm::AxisStatus status_for(uint64_t cycle, uint32_t axis) {
  shm::AxisStatus s;
  s.sample.position_raw = (cycle * 977 + axis) << 16;
  s.sample.periods = static_cast<int64_t>(cycle * 977 + axis);
  s.sample.fresh = true;
  s.validity = shm::AxisValidity::Valid;
  return s;
}

// The former design, replayed on a private mapping with the public layout.
class InlinePublisher {
 public:
  explicit InlinePublisher(uint32_t axes) : axes_(axes) {
    size_ = sizeof(ds1928_shm_header) + axes * sizeof(ds1928_shm_axis);
    map_ = mmap(nullptr, size_, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    wait_ = static_cast<ds1928_shm_wait_area*>(mmap(nullptr, sizeof(ds1928_shm_wait_area),
                                                    PROT_READ | PROT_WRITE,
                                                    MAP_SHARED | MAP_ANONYMOUS, -1, 0));
    header_ = static_cast<ds1928_shm_header*>(map_);
    header_->abi_version = DS1928_SHM_ABI_VERSION;
    header_->header_size = sizeof(ds1928_shm_header);
    header_->record_size = sizeof(ds1928_shm_axis);
    header_->axis_count = axes;
    header_->cycle_period_ns = 1;
    records_ = reinterpret_cast<ds1928_shm_axis*>(header_ + 1);
  }
  ~InlinePublisher() {
    munmap(map_, size_);
    munmap(wait_, sizeof(ds1928_shm_wait_area));
  }
  [[nodiscard]] ds1928_shm_reader reader() const {
    ds1928_shm_reader r{};
    r.header = header_;
    r.size = size_;
    r.wait = wait_;
    return r;
  }
  [[nodiscard]] const ds1928_shm_header* header() const { return header_; }
  void publish(uint64_t cycle, const std::vector<shm::AxisStatus>& st) {
    const int64_t now = ds1928_shm_now_ns();
    for (uint32_t i = 0; i < axes_ && i < st.size(); ++i) {
      ds1928_axis_data d{};
      d.position_raw = st[i].sample.position_raw;
      d.periods = st[i].sample.periods;
      d.publish_ns = now;
      d.cycle = cycle;
      d.check = ds1928_shm_check(&d);
      uint64_t w[DS1928_AXIS_DATA_WORDS];
      std::memcpy(w, &d, sizeof(w));
      const uint64_t s = __atomic_load_n(&records_[i].seq, __ATOMIC_RELAXED);
      __atomic_store_n(&records_[i].seq, s + 1, __ATOMIC_RELAXED);
      __atomic_thread_fence(__ATOMIC_RELEASE);
      for (unsigned k = 0; k < DS1928_AXIS_DATA_WORDS; ++k)
        __atomic_store_n(&records_[i].u.words[k], w[k], __ATOMIC_RELAXED);
      __atomic_store_n(&records_[i].seq, s + 2, __ATOMIC_RELEASE);
    }
    ++count_;
    __atomic_store_n(&header_->last_cycle, cycle, __ATOMIC_RELEASE);
    __atomic_store_n(&header_->last_publish_ns, now, __ATOMIC_RELEASE);
    __atomic_store_n(&header_->publish_count, count_, __ATOMIC_RELEASE);
    __atomic_store_n(&header_->daemon_state, DS1928_DAEMON_RUNNING, __ATOMIC_RELEASE);
    __atomic_fetch_add(&wait_->futex, 1u, __ATOMIC_SEQ_CST);
    uint32_t mask = 0;
    for (unsigned i = 0; i < DS1928_SHM_WAIT_SLOTS; ++i)
      if (__atomic_load_n(&wait_->slots[i].waiters, __ATOMIC_SEQ_CST) != 0) mask |= 1u << i;
    if (mask != 0)
      syscall(SYS_futex, &wait_->futex, FUTEX_WAKE_BITSET, INT_MAX, nullptr, nullptr, mask);
  }
  void stop() {
    __atomic_store_n(&header_->daemon_state, DS1928_DAEMON_STOPPED, __ATOMIC_RELEASE);
    __atomic_fetch_add(&wait_->futex, 1u, __ATOMIC_SEQ_CST);
    syscall(SYS_futex, &wait_->futex, FUTEX_WAKE, INT_MAX, nullptr, nullptr, 0);
  }

 private:
  uint32_t axes_;
  std::size_t size_;
  void* map_;
  ds1928_shm_header* header_;
  ds1928_shm_axis* records_;
  ds1928_shm_wait_area* wait_;
  uint64_t count_ = 0;
};

struct Options {
  uint32_t axes = 4;
  int64_t period_ns = 500'000;
  size_t publications = 4000;
  int rounds = 3;
  int cpu = 1;
  int priority = 80;
};

struct Result {
  std::vector<double> publish_ns;  // cost on the cycle thread
  std::vector<double> wake_ns;     // readers: back from the wait − publication stamp
};

// Sleeping readers on `r` (a mapping of either design) recording their wake-up latency.
class Readers {
 public:
  Readers(ds1928_shm_reader r, unsigned n, int prio, std::vector<double>& out)
      : reader_(r), out_(out) {
    for (unsigned i = 0; i < n; ++i) {
      threads_.emplace_back([this, prio] {
        set_fifo(prio);
        std::vector<double> mine;
        mine.reserve(100'000);
        uint64_t seen = ds1928_shm_wait_start(reader_.header);
        while (!stop_.load(std::memory_order_relaxed)) {
          const int rc = ds1928_shm_wait(&reader_, &seen, 1, ds1928_shm_now_ns() + 200'000'000);
          const int64_t back = ds1928_shm_now_ns();
          if (rc == DS1928_SHM_STOPPED) break;
          if (rc != 0) continue;
          // From the publication's stamp (taken before its records) to the reader having it.
          const int64_t stamp = ds1928_shm_last_publish_ns(reader_.header);
          if (mine.size() < 100'000) mine.push_back(static_cast<double>(back - stamp));
        }
        std::lock_guard<std::mutex> lock(mutex_);
        out_.insert(out_.end(), mine.begin(), mine.end());
      });
    }
    // All asleep before the measurement starts.
    const int64_t deadline = ds1928_shm_now_ns() + 2'000'000'000;
    while (ds1928_shm_now_ns() < deadline) {
      unsigned waiting = 0;
      for (unsigned s = 0; s < DS1928_SHM_WAIT_SLOTS; ++s)
        waiting += __atomic_load_n(&reader_.wait->slots[s].waiters, __ATOMIC_SEQ_CST);
      if (waiting >= n) break;
      usleep(1000);
    }
  }
  void stop() {
    stop_ = true;
    for (auto& t : threads_) t.join();
    threads_.clear();
  }
  ~Readers() {
    if (!threads_.empty()) stop();
  }

 private:
  ds1928_shm_reader reader_;
  std::vector<double>& out_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<std::thread> threads_;
};

// One point: `readers` asleep, `publications` at the period, on the cycle thread.
template <class Publish>
void run_point(const Options& o, Publish&& publish, std::vector<double>& cost, double per_ns) {
  std::thread cycle([&] {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(o.cpu, &set);
    pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
    set_fifo(o.priority);
    std::vector<shm::AxisStatus> st(o.axes);
    std::vector<double> mine;
    mine.reserve(o.publications);
    int64_t next = ds1928_shm_now_ns() + o.period_ns;
    static uint64_t cycle_index = 1000;
    for (size_t i = 0; i < o.publications; ++i) {
      sleep_until(next);
      ++cycle_index;
      for (uint32_t a = 0; a < o.axes; ++a) st[a] = status_for(cycle_index, a);
      const uint64_t t0 = tsc_begin();
      publish(cycle_index, st, next + o.period_ns);
      mine.push_back(static_cast<double>(tsc_end() - t0) / per_ns);
      next += o.period_ns;
    }
    cost.insert(cost.end(), mine.begin(), mine.end());
  });
  cycle.join();
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const long v = std::atol(argv[i + 1]);
    if (k == "--axes")
      o.axes = static_cast<uint32_t>(v);
    else if (k == "--period-us")
      o.period_ns = v * 1000;
    else if (k == "--publications")
      o.publications = static_cast<size_t>(v);
    else if (k == "--rounds")
      o.rounds = static_cast<int>(v);
    else if (k == "--cpu")
      o.cpu = static_cast<int>(v);
    else if (k == "--priority")
      o.priority = static_cast<int>(v);
    else {
      std::fprintf(stderr, "unknown option %s\n", k.c_str());
      return 2;
    }
  }
  mlockall(MCL_CURRENT | MCL_FUTURE);
  const double per_ns = tsc_per_ns();
  const unsigned counts[] = {0, 1, 16};
  Result thread_design[3], inline_design[3];
  uint64_t wake_calls = 0, doorbells = 0;
  for (int round = 0; round < o.rounds; ++round) {
    for (int k = 0; k < 3; ++k) {
      for (int design = 0; design < 2; ++design) {
        const bool thread_first = round % 2 == 0;
        const bool use_thread = (design == 0) == thread_first;
        if (use_thread) {
          const std::string name = "/ds1928d-wakebench-" + std::to_string(getpid());
          shm::Publisher pub;
          ShmConfig cfg;
          cfg.name = name;
          if (auto ec = pub.open(cfg, o.axes, static_cast<uint64_t>(o.period_ns))) {
            std::fprintf(stderr, "open %s: %s\n", name.c_str(), ec.message().c_str());
            return 1;
          }
          (void)pub.place_waker(o.priority - 1, o.cpu);
          ds1928_shm_reader raw{};
          if (ds1928_shm_reader_open(&raw, name.c_str()) != 0 || raw.wait == nullptr) return 1;
          Result& r = thread_design[k];
          {
            Readers readers(raw, counts[k], o.priority - 10, r.wake_ns);
            run_point(
                o, [&](uint64_t c, auto& st, int64_t next) { pub.publish(c, st, next); },
                r.publish_ns, per_ns);
            readers.stop();
          }
          wake_calls += pub.wake_calls();
          doorbells += pub.doorbell_calls();
          pub.close();
          ds1928_shm_reader_close(&raw);
        } else {
          InlinePublisher pub(o.axes);
          Result& r = inline_design[k];
          Readers readers(pub.reader(), counts[k], o.priority - 10, r.wake_ns);
          run_point(
              o, [&](uint64_t c, auto& st, int64_t) { pub.publish(c, st); }, r.publish_ns, per_ns);
          pub.stop();
          readers.stop();
        }
      }
    }
  }
  std::printf(
      "# shm_wake_bench: %u axes, period %lld us, %zu publications x %d rounds per point,"
      " cycle thread FIFO %d on CPU %d, wake-up thread FIFO %d same CPU, readers FIFO %d\n",
      o.axes, static_cast<long long>(o.period_ns / 1000), o.publications, o.rounds, o.priority,
      o.cpu, o.priority - 1, o.priority - 10);
  std::printf("%-8s %-34s %-34s %s\n", "readers", "publish cost p50/p99/max us (now)",
              "publish cost p50/p99/max us (inline)", "wake-up p50/p99/max us now | inline");
  Quantiles none_now = quantiles(thread_design[0].publish_ns);
  for (int k = 0; k < 3; ++k) {
    const Quantiles a = quantiles(thread_design[k].publish_ns);
    const Quantiles b = quantiles(inline_design[k].publish_ns);
    const Quantiles wa = quantiles(thread_design[k].wake_ns);
    const Quantiles wb = quantiles(inline_design[k].wake_ns);
    std::printf("%-8u %6.2f / %6.2f / %8.2f           %6.2f / %6.2f / %8.2f           ", counts[k],
                a.p50 / 1000, a.p99 / 1000, a.max / 1000, b.p50 / 1000, b.p99 / 1000, b.max / 1000);
    if (k == 0)
      std::printf("-\n");
    else
      std::printf("%6.1f / %6.1f / %7.1f | %6.1f / %6.1f / %7.1f  (n %zu | %zu)\n", wa.p50 / 1000,
                  wa.p99 / 1000, wa.max / 1000, wb.p50 / 1000, wb.p99 / 1000, wb.max / 1000, wa.n,
                  wb.n);
  }
  const Quantiles sixteen = quantiles(thread_design[2].publish_ns);
  std::printf(
      "# p99 publish cost with 16 readers asleep over none (now): %+.2f us (goal <= 2 us)\n",
      (sixteen.p99 - none_now.p99) / 1000);
  std::printf("# wake-up thread: %llu FUTEX_WAKE calls, cycle thread rang it %llu times\n",
              static_cast<unsigned long long>(wake_calls),
              static_cast<unsigned long long>(doorbells));
  return 0;
}
