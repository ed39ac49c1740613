#include "shm/publisher.hpp"

#include <grp.h>
#include <signal.h>

#include <atomic>
#include <climits>
#include <cstring>
#include <vector>

#include "core/clock.hpp"
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
  d.flags = static_cast<uint8_t>((s.new_position ? DS1928_AXIS_NEW_POSITION : 0u) |
                                 (s.fraction_valid ? DS1928_AXIS_FRACTION_VALID : 0u) |
                                 (s.fresh ? DS1928_AXIS_FRESH : 0u));
  d.check = ds1928_shm_check(&d);
  return d;
}

// Seqlock write: odd sequence, release fence, the words, even sequence (release).
void write_record(ds1928_shm_axis& record, const ds1928_axis_data& data) noexcept {
  uint64_t words[DS1928_AXIS_DATA_WORDS];
  std::memcpy(words, &data, sizeof(words));
  auto seq = atomic(record.seq);
  const uint64_t s = seq.load(std::memory_order_relaxed);
  seq.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  for (unsigned i = 0; i < DS1928_AXIS_DATA_WORDS; ++i)
    atomic(record.u.words[i]).store(words[i], std::memory_order_relaxed);
  seq.store(s + 2, std::memory_order_release);
}

}  // namespace

std::error_code Publisher::open(const ShmConfig& config, uint32_t axis_count,
                                uint64_t cycle_period_ns) {
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
  const std::size_t size =
      sizeof(ds1928_shm_header) + std::size_t{axis_count} * sizeof(ds1928_shm_axis);
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
  for (uint32_t i = 0; i < axis_count; ++i) {
    ds1928_axis_data empty{};
    empty.validity = DS1928_AXIS_BUS_DOWN;
    empty.check = ds1928_shm_check(&empty);
    write_record(records_[i], empty);
  }
  atomic(header_->daemon_state).store(DS1928_DAEMON_STARTING, std::memory_order_relaxed);
  atomic(header_->magic).store(DS1928_SHM_MAGIC, std::memory_order_release);

  name_ = config.name;
  wait_name_ = wait_name;
  axis_count_ = axis_count;
  generation_ = generation;
  prev_cycle_ = 0;
  publish_count_ = 0;
  wake_calls_ = 0;
  return {};
}

void Publisher::close() noexcept {
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

void Publisher::publish(uint64_t cycle, std::span<const AxisStatus> axes) noexcept {
  if (header_ == nullptr) return;
  const int64_t now = rt::now_ns();  // vDSO, no system call
  const std::size_t n = axes.size() < axis_count_ ? axes.size() : axis_count_;
  for (std::size_t i = 0; i < n; ++i) write_record(records_[i], to_data(axes[i], cycle, now));

  const bool first = publish_count_ == 0;
  ++publish_count_;
  atomic(header_->last_cycle).store(cycle, std::memory_order_release);
  atomic(header_->last_publish_ns).store(now, std::memory_order_release);
  atomic(header_->publish_count).store(publish_count_, std::memory_order_release);
  if (first) set_state(DaemonState::Running);

  // Store the word, then look for waiters (both seq_cst): a reader registers, then reads the
  // word, so one of the two sides always sees the other.
  atomic(wait_->futex).fetch_add(1, std::memory_order_seq_cst);
  uint32_t mask = 0;
  for (unsigned i = 0; i < DS1928_SHM_WAIT_SLOTS; ++i) {
    if (atomic(wait_->slots[i].waiters).load(std::memory_order_seq_cst) == 0) continue;
    const uint32_t factor = atomic(wait_->slots[i].factor).load(std::memory_order_relaxed);
    // Due: a multiple of the factor was published since the last publication (before the
    // first one, waiters hold DS1928_SHM_NO_CYCLE: only a multiple itself is due).
    const bool due =
        factor <= 1 || (first ? cycle % factor == 0 : cycle / factor != prev_cycle_ / factor);
    if (due) mask |= 1u << i;
  }
  prev_cycle_ = cycle;
  if (mask != 0) wake(mask);
}

void Publisher::wake(uint32_t mask) noexcept {
  ++wake_calls_;
  syscall(SYS_futex, &wait_->futex, FUTEX_WAKE_BITSET, INT_MAX, nullptr, nullptr, mask);
}

}  // namespace ds1928::shm
