#include "core/rt_setup.hpp"

#include <fcntl.h>
#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>

namespace ds1928::rt {

SetupStep set_fifo_priority(int priority) noexcept {
  sched_param param{};
  param.sched_priority = priority;
  return SetupStep{pthread_setschedparam(pthread_self(), SCHED_FIFO, &param)};
}

SetupStep pin_to_cpu(int cpu) noexcept {
  if (cpu < 0 || cpu >= CPU_SETSIZE) return SetupStep{EINVAL};
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return SetupStep{pthread_setaffinity_np(pthread_self(), sizeof(set), &set)};
}

namespace {
// The file mappings of the process that are never written: code (r-xp) and, with `rodata`,
// read-only data (r--p: constant tables, string literals, relocation-free data).
void for_each_unwritten_file_mapping(CodeMappingVisitor visit, void* context,
                                     bool rodata) noexcept {
  const int fd = ::open("/proc/self/maps", O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  // Static: a sanitizer build maps hundreds of regions, more than a stack buffer should hold.
  static char buf[1 << 18];
  std::size_t len = 0;
  for (;;) {
    const ssize_t n = ::read(fd, buf + len, sizeof(buf) - 1 - len);
    if (n <= 0) break;
    len += static_cast<std::size_t>(n);
    if (len == sizeof(buf) - 1) break;
  }
  ::close(fd);
  buf[len] = 0;
  for (char* line = buf; line != nullptr && *line != 0;) {
    char* next = std::strchr(line, '\n');
    if (next != nullptr) *next++ = 0;
    unsigned long lo = 0, hi = 0;
    char perms[8] = {};
    int path_at = 0;
    // Code (r-xp: never written) of a file (a path), not [vdso] and the like; with `rodata` also
    // the file's read-only data (r--p).
    if (std::sscanf(line, "%lx-%lx %7s %*s %*s %*s %n", &lo, &hi, perms, &path_at) >= 3 &&
        path_at > 0 && line[path_at] == '/' &&
        (std::strcmp(perms, "r-xp") == 0 || (rodata && std::strcmp(perms, "r--p") == 0)))
      visit(lo, hi, line + path_at, context);
    line = next;
  }
}
}  // namespace

void for_each_code_mapping(CodeMappingVisitor visit, void* context) noexcept {
  for_each_unwritten_file_mapping(visit, context, false);
}

void for_each_unwritten_mapping(CodeMappingVisitor visit, void* context) noexcept {
  for_each_unwritten_file_mapping(visit, context, true);
}

void lock_code_mappings() noexcept {
  for_each_unwritten_mapping([](uintptr_t lo, uintptr_t hi, const char*,
                                void*) { (void)::mlock(reinterpret_cast<void*>(lo), hi - lo); },
                             nullptr);
}

namespace {
// Gives back the pages of the shared libraries' code that start-up touched (the dynamic loader,
// locale and stream initialisation, the configuration parser...) before memory is locked, so
// that mlockall keeps resident only what runs afterwards. Only code mappings (never written, so
// nothing is lost) of files other than the executable; a page used again is simply read back
// from the page cache — by the cycle thread during its first cycles, before it is ready, and
// locked from then on.
void drop_startup_library_code() noexcept {
  // The executable's own code stays as it is.
  static char exe[4096];
  const ssize_t exe_len = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (exe_len <= 0) return;
  exe[exe_len] = 0;
  for_each_code_mapping(
      [](uintptr_t lo, uintptr_t hi, const char* path, void*) {
        if (std::strcmp(path, exe) != 0)
          (void)madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);
      },
      nullptr);
}
}  // namespace

namespace {
struct HeapInfo {
  uintptr_t lo = 0, hi = 0;
  std::size_t resident = 0;
  bool locked = false;  // VmFlags "lo": under mlockall (MCL_FUTURE)
};
// The [heap] mapping (the brk heap of malloc's main arena), from /proc/self/smaps.
HeapInfo heap_info() noexcept {
  HeapInfo h;
  FILE* f = std::fopen("/proc/self/smaps", "re");
  if (f == nullptr) return h;
  char line[512];
  bool in_heap = false;
  while (std::fgets(line, sizeof(line), f) != nullptr) {
    unsigned long lo = 0, hi = 0;
    unsigned long kb = 0;
    if (std::sscanf(line, "%lx-%lx ", &lo, &hi) == 2) {
      in_heap = std::strstr(line, "[heap]") != nullptr;
      if (in_heap) {
        h.lo = lo;
        h.hi = hi;
      }
    } else if (in_heap && std::sscanf(line, "Rss: %lu kB", &kb) == 1) {
      h.resident = kb * 1024;
    } else if (in_heap && std::strncmp(line, "VmFlags:", 8) == 0) {
      h.locked = std::strstr(line, " lo") != nullptr;
    }
  }
  std::fclose(f);
  return h;
}
}  // namespace

std::size_t trim_heap(std::size_t min_free) noexcept {
  const struct mallinfo2 info = mallinfo2();
  if (info.fordblks < min_free) return 0;
  const HeapInfo before = heap_info();
  if (before.hi <= before.lo) return 0;
  if (before.locked) (void)munlock(reinterpret_cast<void*>(before.lo), before.hi - before.lo);
  malloc_trim(0);
  const HeapInfo after = heap_info();
  if (before.locked && after.hi > after.lo)
    (void)mlock2(reinterpret_cast<void*>(after.lo), after.hi - after.lo, MLOCK_ONFAULT);
  return before.resident > after.resident ? before.resident - after.resident : 0;
}

SetupStep lock_all_memory() noexcept {
  drop_startup_library_code();
  // MCL_ONFAULT: a page is locked when it is first touched, not when it is mapped. Without it
  // mlockall loads every page of every shared library the process maps (libgcrypt, libzstd ...
  // pulled in by libsystemd: 11 MB of file pages on the simulated bus, most never executed) and
  // every byte of every reserved buffer. What the cycle thread uses is touched before its first
  // cycles are counted (buffers are built and filled at start, its stack is pre-faulted, its
  // code runs in the first cycles) and from then on locked. A branch of code it first takes
  // later (a CN reset, say) costs one minor fault of a page-cache page, a few µs, once. The
  // proofs of the cycle work count the cycle thread's page faults in steady cycles
  // (tests/daemon/cycle_proof.hpp).
  if (mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) == 0) return {};
  if (errno != EINVAL) return SetupStep{errno};
  // A kernel before 4.4: every page, as before.
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) return SetupStep{errno};
  return {};
}

bool cpu_usable(int cpu) noexcept {
  if (cpu < 0 || cpu >= CPU_SETSIZE) return false;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) != 0) return false;
  return CPU_ISSET(cpu, &set);
}

namespace {
constexpr std::size_t kPage = 4096;

std::size_t round_up_to_page(std::size_t bytes) noexcept {
  return (bytes + kPage - 1) / kPage * kPage;
}

// The calling thread's stack as glibc knows it: [low, low + size), the top holding its TLS.
struct StackBounds {
  const unsigned char* low = nullptr;
  std::size_t size = 0;
};
StackBounds stack_bounds() noexcept {
  StackBounds b;
  pthread_attr_t attr;
  if (pthread_getattr_np(pthread_self(), &attr) != 0) return b;
  void* low = nullptr;
  if (pthread_attr_getstack(&attr, &low, &b.size) == 0)
    b.low = static_cast<const unsigned char*>(low);
  pthread_attr_destroy(&attr);
  return b;
}

void* measure_thread_overhead(void* out) noexcept {
  const StackBounds b = stack_bounds();
  const auto* frame = static_cast<const unsigned char*>(__builtin_frame_address(0));
  if (b.low != nullptr)
    *static_cast<std::size_t*>(out) = static_cast<std::size_t>(b.low + b.size - frame);
  return nullptr;
}
}  // namespace

std::size_t stack_left() noexcept {
  const StackBounds b = stack_bounds();
  const auto* frame = static_cast<const unsigned char*>(__builtin_frame_address(0));
  if (b.low == nullptr || frame <= b.low) return 0;
  return static_cast<std::size_t>(frame - b.low);
}

std::size_t thread_stack_overhead() noexcept {
  // The probe runs on a stack of our own: glibc keeps the stacks it allocated for threads that
  // ended in a cache for reuse, and a cached stack stays mapped — and under mlockall resident —
  // for the life of the process (a probe on the 8 MiB default stack cost 8 MiB of RSS).
  constexpr std::size_t kProbeStack = 4 * 1024 * 1024;  // room for TSan's ~770 KiB of TLS
  void* stack = mmap(nullptr, kProbeStack, PROT_READ | PROT_WRITE,
                     MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (stack == MAP_FAILED) return 0;
  std::size_t overhead = 0;
  pthread_attr_t attr;
  pthread_t probe;
  bool ran = false;
  if (pthread_attr_init(&attr) == 0) {
    if (pthread_attr_setstack(&attr, stack, kProbeStack) == 0 &&
        pthread_create(&probe, &attr, measure_thread_overhead, &overhead) == 0) {
      pthread_join(probe, nullptr);
      ran = true;
    }
    pthread_attr_destroy(&attr);
  }
  munmap(stack, kProbeStack);
  return ran ? overhead : 0;
}

SetupStep limit_default_thread_stack(std::size_t bytes) noexcept {
  // glibc carves a thread's static TLS and descriptor out of its stack. That is a few KiB
  // normally, but TSan keeps ~770 KiB of its own state in TLS: a bare 1 MiB would leave the
  // cycle thread too little to pre-fault its 256 KiB.
  const std::size_t wanted = round_up_to_page(bytes + thread_stack_overhead());
  pthread_attr_t attr;
  if (int e = pthread_getattr_default_np(&attr); e != 0) return SetupStep{e};
  std::size_t current = 0;
  int e = pthread_attr_getstacksize(&attr, &current);
  if (e == 0 && current > wanted) {
    e = pthread_attr_setstacksize(&attr, wanted);
    if (e == 0) e = pthread_setattr_default_np(&attr);
  }
  pthread_attr_destroy(&attr);
  return SetupStep{e};
}

// noinline keeps the frame where the caller expects it: the pages touched here are the ones the
// caller's callees will use.
__attribute__((noinline)) std::size_t prefault_stack(std::size_t bytes) noexcept {
  constexpr std::size_t kMax = 1024 * 1024;
  if (bytes > kMax) bytes = kMax;
  // Never reach the guard page: a thread with a smaller stack than asked pre-faults what it has.
  const std::size_t left = stack_left();
  const std::size_t usable = left > kStackReserve ? left - kStackReserve : 0;
  if (bytes > usable) bytes = usable / kPage * kPage;
  if (bytes == 0) return 0;
  auto* area = static_cast<volatile unsigned char*>(__builtin_alloca(bytes));
  for (std::size_t i = 0; i < bytes; i += kPage) area[i] = 0;
  return bytes;
}

CpuDmaLatencyHold::State CpuDmaLatencyHold::acquire(const char* path) noexcept {
  release();
  fd_ = ::open(path, O_WRONLY | O_CLOEXEC);
  if (fd_ < 0) {
    error_ = errno;
    state_ = error_ == ENOENT ? State::Absent : State::Failed;
    return state_;
  }
  // The PM QoS file takes a binary 32-bit value in µs; the request lasts while the fd is open.
  const int32_t zero = 0;
  if (::write(fd_, &zero, sizeof(zero)) != static_cast<ssize_t>(sizeof(zero))) {
    error_ = errno;
    ::close(fd_);
    fd_ = -1;
    state_ = State::Failed;
    return state_;
  }
  error_ = 0;
  state_ = State::Held;
  return state_;
}

void CpuDmaLatencyHold::release() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (state_ == State::Held) state_ = State::Off;
}

std::string errno_text(int error) {
  return std::strerror(error);
}

}  // namespace ds1928::rt
