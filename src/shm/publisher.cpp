#include "shm/publisher.hpp"

#include <grp.h>
#include <linux/futex.h>
#include <sched.h>
#include <signal.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <climits>
#include <cstring>
#include <vector>

#include "core/clock.hpp"
#include "core/rt_setup.hpp"
#include "shm/shm_error.hpp"

namespace ds1928::shm {
namespace {

std::error_code last_error() noexcept {
  return {errno, std::system_category()};
}

template <class T>
std::atomic_ref<T> atomic(T& value) noexcept {
  return std::atomic_ref<T>(value);
}

bool valid_name(const std::string& name) {
  return name.size() >= 2 && name.front() == '/' && name.find('/', 1) == std::string::npos &&
         name.size() + sizeof(DS1928_SHM_WAIT_SUFFIX) <= NAME_MAX;
}

// A daemon other than us still publishes under `name`.
bool name_held_by_live_daemon(const std::string& name) {
  ds1928_shm_reader reader{};
  if (ds1928_shm_reader_open(&reader, name.c_str()) != 0) return false;
  const auto* h = reader.header;
  if (h == nullptr) return false;  // (open succeeded; tells GCC 12's flow analysis so)
  const bool alive = ds1928_shm_daemon_alive(h, rt::now_ns(), 10) != 0 && h->daemon_pid > 0 &&
                     h->daemon_pid != getpid() && (kill(h->daemon_pid, 0) == 0 || errno == EPERM);
  ds1928_shm_reader_close(&reader);
  return alive;
}

// What already holds `name`. Only a regular file of our own may be replaced (a leftover of a
// dead daemon of ours: its readers keep their mapping); a symbolic link, a FIFO or another
// user's file is left alone, so that nobody can make the daemon write through a planted link or
// hand its readers an object someone else controls. glibc's shm_open adds O_NOFOLLOW (a link
// gives ELOOP); O_NONBLOCK keeps a planted FIFO from blocking the open.
std::error_code check_existing(const std::string& name) {
  const int fd = shm_open(name.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC, 0);
  if (fd < 0) {
    if (errno == ENOENT) return {};
    if (errno == ELOOP) return ShmError::kNotRegularFile;
    return last_error();
  }
  struct stat st {};
  const int rc = fstat(fd, &st);
  const auto ec = last_error();
  ::close(fd);
  if (rc != 0) return ec;
  if (!S_ISREG(st.st_mode)) return ShmError::kNotRegularFile;
  if (st.st_uid != geteuid()) return ShmError::kForeignOwner;
  return {};
}

std::error_code create_object(const std::string& name, uint32_t mode, int gid, std::size_t size,
                              int& fd_out, void*& map_out) {
  if (auto ec = check_existing(name)) return ec;
  shm_unlink(name.c_str());  // a leftover of a dead daemon of ours
  const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) return last_error();
  auto fail = [&] {
    const auto ec = last_error();
    ::close(fd);
    shm_unlink(name.c_str());
    return ec;
  };
  // Mode and group explicitly: shm_open's mode is filtered by the umask.
  if (ftruncate(fd, static_cast<off_t>(size)) != 0) return fail();
  // The file takes the daemon's group; chown only to change it (the packaged unit's syscall
  // filter refuses chown, and its group already is the readers' group).
  struct stat st {};
  if (fstat(fd, &st) != 0) return fail();
  if (gid >= 0 && st.st_gid != static_cast<gid_t>(gid) &&
      fchown(fd, static_cast<uid_t>(-1), static_cast<gid_t>(gid)) != 0)
    return fail();
  if (fchmod(fd, static_cast<mode_t>(mode & 07777)) != 0) return fail();
  void* p = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) return fail();
  // Pre-fault now so that the cycle thread never takes a page fault on its first publication;
  // lock it if we may (mlockall(MCL_FUTURE) of the engine covers it too).
  std::memset(p, 0, size);
  (void)mlock(p, size);
  fd_out = fd;
  map_out = p;
  return {};
}

// Unlinks `name` only if it still refers to the object behind `fd`.
void unlink_if_ours(const std::string& name, int fd) noexcept {
  struct stat ours {};
  if (fstat(fd, &ours) != 0) return;
  const int other = shm_open(name.c_str(), O_RDONLY | O_CLOEXEC, 0);
  if (other < 0) return;
  struct stat theirs {};
  const bool same =
      fstat(other, &theirs) == 0 && theirs.st_ino == ours.st_ino && theirs.st_dev == ours.st_dev;
  ::close(other);
  if (same) shm_unlink(name.c_str());
}

ds1928_axis_data to_data(const AxisStatus& status, uint64_t cycle, int64_t now_ns) noexcept {
  const AxisSample& s = status.sample;
  ds1928_axis_data d{};
  d.position_raw = s.position_raw;
  d.periods = s.periods;
  d.pos_time_ns = s.pos_time_ns;
  d.publish_ns = now_ns;
  d.cycle = cycle;
  d.position_sdc = s.position_sdc;
  d.pos_time_raw = s.pos_time_raw;
  d.endat_error = status.endat_error;
  d.endat_warning = status.endat_warning;
  d.fraction = s.fraction;
  d.time_source = static_cast<uint8_t>(s.time_source);
  d.pos_cycle = s.pos_cycle;
  d.error_info = s.error_info;
  d.validity = static_cast<uint8_t>(status.validity);
  d.flags = static_cast<uint8_t>(
      (s.new_position ? DS1928_AXIS_NEW_POSITION : 0u) |
      (s.fraction_valid ? DS1928_AXIS_FRACTION_VALID : 0u) | (s.fresh ? DS1928_AXIS_FRESH : 0u) |
      (status.errors.fault ? DS1928_AXIS_FAULT : 0u) |
      (status.errors.warning ? DS1928_AXIS_WARNING : 0u) | (s.held ? DS1928_AXIS_HELD : 0u));
  d.check = ds1928_shm_check(&d);
  return d;
}

ds1928_axis_info to_info(const AxisInfo& info, int64_t now_ns) noexcept {
  ds1928_axis_info out{};
  for (std::size_t n = 0; n < kInfoChannels; ++n) {
    out.value[n] = info.value[n];
    out.age_us[n] = info_age_us(info, n, now_ns);
  }
  out.valid = info.valid;
  out.configured = info.configured;
  return out;
}

// Seqlock write: odd sequence, release fence, the words (payload and channels), even sequence
// (release).
void write_record(ds1928_shm_axis& record, const ds1928_axis_data& data,
                  const ds1928_axis_info& info) noexcept {
  uint64_t words[DS1928_AXIS_DATA_WORDS];
  std::memcpy(words, &data, sizeof(words));
  uint64_t info_words[DS1928_AXIS_INFO_WORDS];
  std::memcpy(info_words, &info, sizeof(info_words));
  auto seq = atomic(record.seq);
  const uint64_t s = seq.load(std::memory_order_relaxed);
  seq.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  for (unsigned i = 0; i < DS1928_AXIS_DATA_WORDS; ++i)
    atomic(record.u.words[i]).store(words[i], std::memory_order_relaxed);
  for (unsigned i = 0; i < DS1928_AXIS_INFO_WORDS; ++i)
    atomic(record.x.words[i]).store(info_words[i], std::memory_order_relaxed);
  seq.store(s + 2, std::memory_order_release);
}

// A waiter seen this recently keeps the wake-up thread following the publications; after that
// long without one it goes idle and the cycle thread rings it again when a reader registers.
constexpr int64_t kWakerIdleAfterNs = 1'000'000'000;
// resume_after_ while no publication has rung the idle waker yet.
constexpr uint64_t kResumePending = DS1928_SHM_NO_CYCLE - 1;

// Sleeps on a process-private futex word until it differs from `expected`, it is woken, or the
// absolute CLOCK_MONOTONIC `deadline_ns` passes (0 = no deadline). FUTEX_WAIT_BITSET takes an
// absolute time, so a late wake-up never adds up, like clock_nanosleep(TIMER_ABSTIME).
void futex_wait_until(std::atomic<uint32_t>& word, uint32_t expected, int64_t deadline_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline_ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(deadline_ns % 1'000'000'000);
  syscall(SYS_futex, reinterpret_cast<uint32_t*>(&word), FUTEX_WAIT_BITSET | FUTEX_PRIVATE_FLAG,
          expected, deadline_ns > 0 ? &ts : nullptr, nullptr, FUTEX_BITSET_MATCH_ANY);
}

void futex_wake_all(std::atomic<uint32_t>& word) {
  syscall(SYS_futex, reinterpret_cast<uint32_t*>(&word), FUTEX_WAKE | FUTEX_PRIVATE_FLAG, INT_MAX,
          nullptr, nullptr, 0);
}

}  // namespace

std::error_code Publisher::open(const ShmConfig& config, uint32_t axis_count,
                                uint64_t cycle_period_ns, std::span<const InfoNames> info_names) {
  close();
  if (!valid_name(config.name)) return ShmError::kInvalidName;
  // No axes is valid (a POWERLINK MN with generic CNs only): the header alone still tells
  // readers that the daemon runs and at which cycle.
  if (axis_count > kMaxAxes) return ShmError::kTooManyAxes;
  int gid = -1;
  if (!config.group.empty()) {
    group grp{};
    group* found = nullptr;
    std::vector<char> buffer(16384);
    if (getgrnam_r(config.group.c_str(), &grp, buffer.data(), buffer.size(), &found) != 0 ||
        found == nullptr)
      return ShmError::kUnknownGroup;
    gid = static_cast<int>(found->gr_gid);
  }
  // Ownership and type first: the liveness probe maps whatever holds the name.
  if (auto ec = check_existing(config.name)) return ec;
  if (name_held_by_live_daemon(config.name)) return ShmError::kNameInUse;

  const std::string wait_name = config.name + DS1928_SHM_WAIT_SUFFIX;
  // The records, then the channels' names table (a reader of the version 1 base ignores it).
  const std::size_t names_offset =
      sizeof(ds1928_shm_header) + std::size_t{axis_count} * sizeof(ds1928_shm_axis);
  const std::size_t size =
      names_offset + std::size_t{axis_count} * DS1928_INFO_CHANNELS * DS1928_INFO_NAME_LEN;
  // Readers register in the wait area, so it is writable wherever the data is readable.
  const uint32_t wait_mode = config.mode | ((config.mode & 0444) >> 1);
  const uint64_t generation = static_cast<uint64_t>(rt::realtime_ns());

  // The wait area first: a reader that finds the data object complete finds its wait area too.
  void* wait_map = nullptr;
  if (auto ec = create_object(wait_name, wait_mode, gid, sizeof(ds1928_shm_wait_area), wait_fd_,
                              wait_map))
    return ec;
  wait_ = static_cast<ds1928_shm_wait_area*>(wait_map);
  wait_->generation = generation;
  atomic(wait_->magic).store(DS1928_SHM_WAIT_MAGIC, std::memory_order_release);

  void* map = nullptr;
  if (auto ec = create_object(config.name, config.mode, gid, size, fd_, map)) {
    munmap(wait_, sizeof(ds1928_shm_wait_area));
    wait_ = nullptr;
    unlink_if_ours(wait_name, wait_fd_);
    ::close(wait_fd_);
    wait_fd_ = -1;
    return ec;
  }
  header_ = static_cast<ds1928_shm_header*>(map);
  records_ =
      reinterpret_cast<ds1928_shm_axis*>(static_cast<char*>(map) + sizeof(ds1928_shm_header));
  size_ = size;
  header_->abi_version = DS1928_SHM_ABI_VERSION;
  header_->header_size = sizeof(ds1928_shm_header);
  header_->record_size = sizeof(ds1928_shm_axis);
  header_->axis_count = axis_count;
  header_->generation = generation;
  header_->cycle_period_ns = cycle_period_ns;
  header_->daemon_pid = static_cast<int32_t>(getpid());
  // The time base fields are atomic; t0 stays 0 until the first cycle with a context.
  header_->features = DS1928_SHM_FEATURE_TIMEBASE | DS1928_SHM_FEATURE_INFO;
  header_->info_names_offset = static_cast<uint32_t>(names_offset);
  char* names = static_cast<char*>(map) + names_offset;
  for (std::size_t a = 0; a < std::min<std::size_t>(axis_count, info_names.size()); ++a)
    for (std::size_t n = 0; n < kInfoChannels; ++n) {
      const std::string& name = info_names[a][n];
      std::memcpy(names + (a * DS1928_INFO_CHANNELS + n) * DS1928_INFO_NAME_LEN, name.data(),
                  std::min<std::size_t>(name.size(), DS1928_INFO_NAME_LEN - 1));
    }
  for (uint32_t i = 0; i < axis_count; ++i) {
    ds1928_axis_data empty{};
    empty.validity = DS1928_AXIS_BUS_DOWN;
    empty.check = ds1928_shm_check(&empty);
    ds1928_axis_info none{};
    for (uint32_t& age : none.age_us) age = DS1928_INFO_AGE_NEVER;
    write_record(records_[i], empty, none);
  }
  atomic(header_->daemon_state).store(DS1928_DAEMON_STARTING, std::memory_order_relaxed);
  atomic(header_->magic).store(DS1928_SHM_MAGIC, std::memory_order_release);

  name_ = config.name;
  wait_name_ = wait_name;
  axis_count_ = axis_count;
  generation_ = generation;
  period_ns_ = static_cast<int64_t>(cycle_period_ns);
  prev_cycle_ = 0;
  publish_count_ = 0;
  offset_hist_.assign(kOffsetBuckets, 0u);
  offset_bucket_ns_ = std::max<int64_t>(1, (period_ns_ + kOffsetBuckets - 1) / kOffsetBuckets);
  window_count_ = 0;
  window_max_ns_ = 0;
  first_window_ = true;
  acq_max_.assign(axis_count, 0u);
  published_t0_ = 0;
  wake_calls_.store(0, std::memory_order_relaxed);
  doorbell_calls_.store(0, std::memory_order_relaxed);
  if (!start_waker()) {
    close();
    return std::error_code(EAGAIN, std::system_category());
  }
  return {};
}

bool Publisher::start_waker() noexcept {
  pthread_attr_t attr;
  if (pthread_attr_init(&attr) != 0) return false;
  // An explicit stack: the process default (1 MiB in the daemon) would be locked whole by
  // mlockall for a loop that needs a few hundred bytes. glibc takes the TLS from the same block.
  std::size_t stack = kWakerStackBytes + rt::thread_stack_overhead();
  stack = (stack + 4095) / 4096 * 4096;
  if (stack < static_cast<std::size_t>(PTHREAD_STACK_MIN))
    stack = static_cast<std::size_t>(PTHREAD_STACK_MIN);
  (void)pthread_attr_setstacksize(&attr, stack);
  waker_stop_.store(false, std::memory_order_relaxed);
  // Idle until the first reader registers: the cycle thread rings it then.
  waker_idle_.store(true, std::memory_order_relaxed);
  resume_after_.store(kResumePending, std::memory_order_relaxed);
  waker_follows_.store(false, std::memory_order_relaxed);
  next_wake_ns_.store(0, std::memory_order_relaxed);
  next_publish_ns_.store(0, std::memory_order_relaxed);
  const int rc = pthread_create(&waker_, &attr, &Publisher::waker_entry, this);
  pthread_attr_destroy(&attr);
  if (rc != 0) return false;
  waker_started_ = true;
  pthread_setname_np(waker_, "ds1928-shmwake");
  return true;
}

void Publisher::stop_waker() noexcept {
  if (!waker_started_) return;
  waker_stop_.store(true, std::memory_order_seq_cst);
  doorbell_.fetch_add(1, std::memory_order_seq_cst);
  futex_wake_all(doorbell_);
  pthread_join(waker_, nullptr);
  waker_started_ = false;
}

int Publisher::place_waker(int rt_priority, int cpu) noexcept {
  if (!waker_started_) return ESRCH;
  int first_error = 0;
  if (cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    if (const int rc = pthread_setaffinity_np(waker_, sizeof(set), &set); rc != 0) first_error = rc;
  }
  if (rt_priority > 0) {
    sched_param param{};
    param.sched_priority = rt_priority;
    if (const int rc = pthread_setschedparam(waker_, SCHED_FIFO, &param);
        rc != 0 && first_error == 0)
      first_error = rc;
  }
  // Follow the cycle thread's own timeline only where the CPU is shared for sure.
  waker_follows_.store(cpu >= 0 && first_error == 0, std::memory_order_relaxed);
  // The flag is read by the waker at its next pass; a ring makes that pass now.
  doorbell_.fetch_add(1, std::memory_order_seq_cst);
  futex_wake_all(doorbell_);
  return first_error;
}

void* Publisher::waker_entry(void* self) noexcept {
  static_cast<Publisher*>(self)->waker_main();
  return nullptr;
}

bool Publisher::any_waiter() const noexcept {
  for (unsigned i = 0; i < DS1928_SHM_WAIT_SLOTS; ++i)
    if (atomic(wait_->slots[i].waiters).load(std::memory_order_seq_cst) != 0) return true;
  return false;
}

// Slots with waiters that a publication in (seen_cycle, last] is due for (before the first
// publication, waiters hold DS1928_SHM_NO_CYCLE: only a multiple itself is due).
uint32_t Publisher::due_mask(uint64_t seen_cycle, uint64_t last) const noexcept {
  uint32_t mask = 0;
  for (unsigned i = 0; i < DS1928_SHM_WAIT_SLOTS; ++i) {
    if (atomic(wait_->slots[i].waiters).load(std::memory_order_seq_cst) == 0) continue;
    const uint32_t factor = atomic(wait_->slots[i].factor).load(std::memory_order_relaxed);
    const bool due =
        factor <= 1 || (seen_cycle == DS1928_SHM_NO_CYCLE ? last % factor == 0
                                                          : last / factor != seen_cycle / factor);
    if (due) mask |= 1u << i;
  }
  return mask;
}

// The wake-up thread. Active, it looks at the futex word once per publication: it sleeps until
// the cycle thread's next wake-up (pinned to its CPU at a lower priority, it therefore runs the
// moment the cycle thread, having published, goes back to sleep) or until the predicted next
// publication, then polls in short steps while the publication is not there yet. Then it reads
// the registrations and makes the FUTEX_WAKE_BITSET for the due slots. Correctness does not
// depend on the timing: it loads the word, then the registrations (both sequentially
// consistent) after the cycle thread stored the word, exactly where the cycle thread used to.
void Publisher::waker_main() noexcept {
  uint32_t seen_word = 0;
  uint64_t seen_cycle = DS1928_SHM_NO_CYCLE;
  int64_t last_waiter_ns = 0;
  const int64_t step = period_ns_ / 32 > 5'000 ? period_ns_ / 32 : 5'000;
  // Idle: sleeps until publish() rings (it stored where to resume first) or stop.
  auto sleep_while_idle = [&]() -> bool {
    while (waker_idle_.load(std::memory_order_seq_cst)) {
      if (waker_stop_.load(std::memory_order_acquire)) return false;
      const uint32_t bell = doorbell_.load(std::memory_order_seq_cst);
      if (waker_idle_.load(std::memory_order_seq_cst) &&
          !waker_stop_.load(std::memory_order_acquire))
        futex_wait_until(doorbell_, bell, 0);
    }
    // The publication that rang and every later one are ours to look at.
    seen_cycle = resume_after_.load(std::memory_order_acquire);
    seen_word = atomic(wait_->futex).load(std::memory_order_seq_cst) - 1;  // look at once
    last_waiter_ns = rt::now_ns();
    return true;
  };
  if (!sleep_while_idle()) return;
  while (!waker_stop_.load(std::memory_order_acquire)) {
    const uint32_t word = atomic(wait_->futex).load(std::memory_order_seq_cst);
    if (word != seen_word) {
      seen_word = word;
      if (atomic(header_->publish_count).load(std::memory_order_acquire) == 0) continue;
      const uint64_t last = atomic(header_->last_cycle).load(std::memory_order_acquire);
      const uint32_t mask = due_mask(seen_cycle, last);
      seen_cycle = last;
      if (mask != 0) wake(mask);
      const int64_t now = rt::now_ns();
      if (mask != 0 || any_waiter()) {
        last_waiter_ns = now;
      } else if (now - last_waiter_ns > kWakerIdleAfterNs) {
        // Idle. The flag is announced (seq_cst) before the last look at the registrations, so a
        // registration that raced this decision is seen here or by publish().
        resume_after_.store(kResumePending, std::memory_order_relaxed);
        waker_idle_.store(true, std::memory_order_seq_cst);
        if (any_waiter() && waker_idle_.exchange(false, std::memory_order_seq_cst)) {
          last_waiter_ns = now;
        } else if (!sleep_while_idle()) {
          return;
        }
      }
      continue;
    }
    // Nothing new: sleep until the publication should be there (doorbell_ only changes to stop
    // or to re-place this thread).
    const int64_t now = rt::now_ns();
    int64_t target = waker_follows_.load(std::memory_order_relaxed)
                         ? next_wake_ns_.load(std::memory_order_relaxed)
                         : next_publish_ns_.load(std::memory_order_relaxed);
    if (target <= now) target = now + step;
    futex_wait_until(doorbell_, doorbell_.load(std::memory_order_relaxed), target);
  }
}

void Publisher::close() noexcept {
  stop_waker();
  if (header_ == nullptr) return;
  set_state(DaemonState::Stopped);
  // Waiters return DS1928_SHM_STOPPED: change the word so that a reader about to sleep sees it.
  atomic(wait_->futex).fetch_add(1, std::memory_order_seq_cst);
  wake(~0u);
  munmap(header_, size_);
  munmap(wait_, sizeof(ds1928_shm_wait_area));
  unlink_if_ours(name_, fd_);
  unlink_if_ours(wait_name_, wait_fd_);
  ::close(fd_);
  ::close(wait_fd_);
  header_ = nullptr;
  records_ = nullptr;
  wait_ = nullptr;
  fd_ = wait_fd_ = -1;
  size_ = 0;
  axis_count_ = 0;
}

void Publisher::set_state(DaemonState state) noexcept {
  if (header_ == nullptr) return;
  atomic(header_->daemon_state).store(static_cast<uint32_t>(state), std::memory_order_release);
}

void Publisher::publish(uint64_t cycle, std::span<const AxisStatus> axes,
                        int64_t next_wake_ns) noexcept {
  if (header_ == nullptr) return;
  const int64_t now = rt::now_ns();  // vDSO, no system call
  publish_records(cycle, axes, now);
  publish_header(cycle, now, next_wake_ns);
}

void Publisher::publish(const CycleContext& ctx, std::span<const AxisStatus> axes,
                        int64_t next_wake_ns) noexcept {
  if (header_ == nullptr) return;
  const int64_t now = rt::now_ns();
  publish_records(ctx.index, axes, now);
  measure(ctx, now);
  publish_header(ctx.index, now, next_wake_ns);
}

void Publisher::publish_records(uint64_t cycle, std::span<const AxisStatus> axes,
                                int64_t now) noexcept {
  const std::size_t n = axes.size() < axis_count_ ? axes.size() : axis_count_;
  for (std::size_t i = 0; i < n; ++i)
    write_record(records_[i], to_data(axes[i], cycle, now), to_info(axes[i].info, now));
}

namespace {
uint32_t clamp_u32(int64_t ns) noexcept {
  if (ns < 0) return 0;
  return ns > int64_t{UINT32_MAX} ? UINT32_MAX : static_cast<uint32_t>(ns);
}
}  // namespace

// The time base and its measurement: a histogram of the publication's offset in the cycle and
// each axis' largest acquisition-to-publication time over a window; the header gets the
// window's p50, p99 and max when it closes (and early results after 64 and 256 publications of
// the first window, so a reader needs not wait a second). Fixed buffers, no system call.
void Publisher::measure(const CycleContext& ctx, int64_t now) noexcept {
  if (ctx.t0_ns != published_t0_) {
    published_t0_ = ctx.t0_ns;
    atomic(header_->timebase_t0_ns).store(ctx.t0_ns, std::memory_order_release);
  }
  if (ctx.timebase != nullptr) {
    const TimebaseStatus& tb = *ctx.timebase;
    atomic(header_->timebase_tai_offset_ns).store(tb.tai_offset_ns, std::memory_order_relaxed);
    atomic(header_->timebase_kind).store(static_cast<uint32_t>(tb.kind), std::memory_order_relaxed);
    atomic(header_->timebase_last_step_ns).store(tb.last_step_ns, std::memory_order_relaxed);
    atomic(header_->timebase_steps).store(tb.steps, std::memory_order_release);
  }
  const int64_t offset = now - ctx.start_ns < 0 ? 0 : now - ctx.start_ns;
  std::size_t bucket = static_cast<std::size_t>(offset / offset_bucket_ns_);
  if (bucket >= offset_hist_.size()) bucket = offset_hist_.size() - 1;
  ++offset_hist_[bucket];
  if (offset > window_max_ns_) window_max_ns_ = offset;
  const std::size_t n = static_cast<std::size_t>(axis_count_);
  for (std::size_t i = 0; i < n; ++i) {
    const ds1928_axis_data& d = records_[i].u.data;  // written by this thread just now
    uint32_t acq = 0;
    if ((d.flags & DS1928_AXIS_FRESH) != 0 && d.pos_time_ns != 0) {
      acq = clamp_u32(now - d.pos_time_ns);
      if (acq > acq_max_[i]) acq_max_[i] = acq;
    }
    atomic(records_[i].acq_to_publish_ns).store(acq, std::memory_order_relaxed);
  }
  ++window_count_;
  const bool close_window = window_count_ >= kTimebaseWindow;
  if (!close_window && !(first_window_ && (window_count_ == 64 || window_count_ == 256))) return;
  // Percentiles from the histogram: the upper edge of the bucket that holds the rank.
  auto percentile = [&](uint32_t permille) {
    const uint64_t rank = (uint64_t{window_count_} * permille + 999) / 1000;
    uint64_t seen = 0;
    for (std::size_t b = 0; b < offset_hist_.size(); ++b) {
      seen += offset_hist_[b];
      if (seen >= rank) return (static_cast<int64_t>(b) + 1) * offset_bucket_ns_;
    }
    return window_max_ns_;
  };
  const int64_t p50 = std::min(percentile(500), window_max_ns_);
  const int64_t p99 = std::min(percentile(990), window_max_ns_);
  atomic(header_->publish_offset_p50_ns).store(clamp_u32(p50), std::memory_order_relaxed);
  atomic(header_->publish_offset_max_ns)
      .store(clamp_u32(window_max_ns_), std::memory_order_relaxed);
  atomic(header_->publish_offset_p99_ns).store(clamp_u32(p99), std::memory_order_release);
  for (std::size_t i = 0; i < n; ++i)
    atomic(records_[i].acq_to_publish_max_ns).store(acq_max_[i], std::memory_order_relaxed);
  if (!close_window) return;
  first_window_ = false;
  window_count_ = 0;
  window_max_ns_ = 0;
  std::fill(offset_hist_.begin(), offset_hist_.end(), 0u);
  std::fill(acq_max_.begin(), acq_max_.end(), 0u);
}

void Publisher::publish_header(uint64_t cycle, int64_t now, int64_t next_wake_ns) noexcept {
  const bool first = publish_count_ == 0;
  ++publish_count_;
  atomic(header_->last_cycle).store(cycle, std::memory_order_release);
  atomic(header_->last_publish_ns).store(now, std::memory_order_release);
  atomic(header_->publish_count).store(publish_count_, std::memory_order_release);
  if (first) set_state(DaemonState::Running);

  next_wake_ns_.store(next_wake_ns, std::memory_order_relaxed);
  next_publish_ns_.store(now + period_ns_, std::memory_order_relaxed);
  // Store the word (seq_cst). The wake-up thread reads it, then the registrations; a reader
  // registers, then reads the word: one of the two sides always sees the other.
  atomic(wait_->futex).fetch_add(1, std::memory_order_seq_cst);
  // An idle wake-up thread reads nothing, so here the cycle thread looks at the registrations
  // itself (16 loads) and rings it: the one system call, once per idle -> active transition.
  // The waker announces idleness (seq_cst) before its last look at the registrations, so a
  // registration it missed is seen here.
  if (waker_idle_.load(std::memory_order_seq_cst) && any_waiter()) {
    // Where the waker resumes: after the previous publication, so this one counts as new to
    // it. Stored before the flag changes, read after the waker sees it changed.
    resume_after_.store(first ? DS1928_SHM_NO_CYCLE : prev_cycle_, std::memory_order_relaxed);
  }
  if (waker_idle_.load(std::memory_order_seq_cst) && any_waiter() &&
      waker_idle_.exchange(false, std::memory_order_seq_cst)) {
    doorbell_.fetch_add(1, std::memory_order_seq_cst);
    doorbell_calls_.store(doorbell_calls_.load(std::memory_order_relaxed) + 1,
                          std::memory_order_relaxed);
    futex_wake_all(doorbell_);
  }
  prev_cycle_ = cycle;
}

void Publisher::wake(uint32_t mask) noexcept {
  wake_calls_.fetch_add(1, std::memory_order_relaxed);
  syscall(SYS_futex, &wait_->futex, FUTEX_WAKE_BITSET, INT_MAX, nullptr, nullptr, mask);
}

}  // namespace ds1928::shm
