// The pieces of real-time setup the cycle engine is made of (beside the clock, core/clock.hpp):
// scheduling, CPU affinity, memory locking, stack pre-faulting and the /dev/cpu_dma_latency
// request. Each is a small function so tests and the benchmark can use the same calls the engine
// uses.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "core/clock.hpp"  // now_ns, sleep_until: the clock the engine runs on

namespace ds1928::rt {

// Result of one setup step: 0 or the errno of the failing call.
struct SetupStep {
  int error = 0;
  [[nodiscard]] bool ok() const noexcept { return error == 0; }
};

// SCHED_FIFO at `priority` for the calling thread.
[[nodiscard]] SetupStep set_fifo_priority(int priority) noexcept;
// Pins the calling thread to `cpu`.
[[nodiscard]] SetupStep pin_to_cpu(int cpu) noexcept;
// mlockall(MCL_CURRENT | MCL_FUTURE): process-wide, never undone (a daemon that locked its
// memory once wants it locked for its lifetime).
[[nodiscard]] SetupStep lock_all_memory() noexcept;
// Makes `bytes` the usable stack of threads created from now on without their own attributes
// (glibc's default follows RLIMIT_STACK, usually 8 MiB). With mlockall(MCL_FUTURE) every thread's
// whole stack is locked in RAM, so the default decides the daemon's resident size. The size set
// is `bytes` plus what glibc takes from each stack for TLS (thread_stack_overhead()). Never
// raises the default. Call before the first thread is started.
[[nodiscard]] SetupStep limit_default_thread_stack(std::size_t bytes) noexcept;
// Bytes at the top of a new thread's stack that its code cannot use (static TLS, thread
// descriptor), measured on a probe thread started with the current defaults. 0 if that fails.
[[nodiscard]] std::size_t thread_stack_overhead() noexcept;
// Bytes of the calling thread's stack below the caller's frame, 0 if glibc cannot say.
[[nodiscard]] std::size_t stack_left() noexcept;

// Stack that prefault_stack() leaves untouched below its own frame, for signal handlers and
// for what the sanitizer runtimes put on the stack.
inline constexpr std::size_t kStackReserve = 64 * 1024;
// Touches up to `bytes` of the calling thread's stack so that the first deep call on the RT path
// does not page-fault, and returns how many it touched: fewer when the stack left, less
// kStackReserve, is smaller.
[[nodiscard]] std::size_t prefault_stack(std::size_t bytes) noexcept;
// Normal thread: gives the main heap's free pages back to the kernel when more than `min_free`
// bytes are free in it, and returns how many bytes the heap's resident size shrank by. Under
// mlockall free heap pages stay resident (malloc_trim's MADV_DONTNEED is refused on locked
// pages), so the heap range is unlocked for the trim and locked again (on fault) right after:
// pages in use stay resident throughout (unlocking does not evict), the free ones go.
std::size_t trim_heap(std::size_t min_free) noexcept;
// Each code mapping of the process (the executable's and its libraries': r-xp mappings of a file
// in /proc/self/maps): visit(lo, hi, path, context). Start-up and tests only — it reads the
// file into one static buffer, so two threads must not call it at once.
using CodeMappingVisitor = void (*)(uintptr_t lo, uintptr_t hi, const char* path, void* context);
void for_each_code_mapping(CodeMappingVisitor visit, void* context) noexcept;
// Each file mapping that is never written: the code mappings above and the files' read-only data
// (r--p: constant tables such as libm's __sincostab, which sin() reads a page of only for some
// arguments). Same rules as for_each_code_mapping.
void for_each_unwritten_mapping(CodeMappingVisitor visit, void* context) noexcept;
// Loads and locks every code mapping and every read-only data mapping of a file (mlock). With
// mlockall(MCL_ONFAULT) both are locked as they are first used; after this no branch taken later,
// and no table entry read for the first time, costs a page fault.
void lock_code_mappings() noexcept;
// Whether `cpu` exists and the process may run on it.
[[nodiscard]] bool cpu_usable(int cpu) noexcept;

// Holds /dev/cpu_dma_latency open with 0 written, which keeps the CPUs out of deep idle states
// for as long as the file stays open (the PM QoS interface cyclictest uses). A missing file is
// not an error (state() == Absent).
class CpuDmaLatencyHold {
 public:
  enum class State : uint8_t { Off, Held, Absent, Failed };

  CpuDmaLatencyHold() = default;
  ~CpuDmaLatencyHold() { release(); }
  CpuDmaLatencyHold(const CpuDmaLatencyHold&) = delete;
  CpuDmaLatencyHold& operator=(const CpuDmaLatencyHold&) = delete;

  // Opens the file and writes 0. Returns the new state; on Failed, error() is the errno.
  State acquire(const char* path = "/dev/cpu_dma_latency") noexcept;
  void release() noexcept;
  [[nodiscard]] State state() const noexcept { return state_; }
  [[nodiscard]] int error() const noexcept { return error_; }

 private:
  int fd_ = -1;
  State state_ = State::Off;
  int error_ = 0;
};

// "Operation not permitted" etc., without the allocation-free constraint (normal thread only).
[[nodiscard]] std::string errno_text(int error);

}  // namespace ds1928::rt
