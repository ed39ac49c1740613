// The two halves of the allocation proofs of the daemon's cycle work (simulated bus and
// POWERLINK): CountingTask counts heap allocations, mutex locks and page faults (minor and
// major: the daemon locks memory as it is first touched, so a page the cycle thread touches
// late would fault) on the cycle thread over a window of cycles; CycleTraffic is the normal
// thread's side, one round of the traffic a running daemon puts through its cycle work — an EnDat
// command into every axis' Flatstream tunnel, replies collected, an error acknowledgement, an
// acyclic register read — counted so the proofs can require that it really went through the counted
// cycles.
#pragma once

#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cstdint>

#include "core/bus.hpp"
#include "core/cycle_engine.hpp"
#include "core/rt_setup.hpp"
#include "cycle_work.hpp"
#include "endat/command.hpp"
#include "support/alloc_counter.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::test {

// Wraps the daemon's CycleTask and counts `counted` cycles: from the first cycle after `warmup`
// cycles once armed (from the start when `armed`, else from arm()). `open_ended`: `counted` is the
// least, and the window closes at the first cycle after close() — a test whose window must hold
// traffic from other threads (a node thread, SDO answers) closes it once that traffic was seen,
// so what the window contains does not depend on how the scheduler shares the cores.
class CountingTask final : public CycleTask {
 public:
  CountingTask(CycleTask& inner, uint64_t counted, uint64_t warmup = 0, bool armed = true,
               bool open_ended = false)
      : inner_(inner), counted_(counted), warmup_(warmup), armed_(armed), close_(!open_ended) {}
  void run_cycle(const CycleContext& ctx) noexcept override {
    if (!counting_ && !done() && executed_ >= warmup_ && armed_.load(std::memory_order_acquire)) {
      counting_ = true;
      // Every code mapping locked, outside what the window counts (before its first reading).
      // The daemon locks memory as it is first touched (mlockall with MCL_ONFAULT), so a branch
      // of code the cycle thread first takes costs one page fault, once; which branches it first
      // takes inside a window depends on how the scheduler shares the cores (a register result
      // held because the normal thread polled late, a tunnel reply that waits one cycle more).
      // The files' read-only data is locked with it: the simulated encoder's sine profile reads
      // libm's __sincostab, a page of which only some arguments reach (once counted as the
      // window's one fault, under memory load). Locked before, a fault the window counts is a
      // written data page the cycle touched for the first time in steady cycles, which is what
      // the proofs are about.
      rt::lock_code_mappings();
      faults_at_start_ = thread_faults();
      begin_counting();
    }
    inner_.run_cycle(ctx);
    ++executed_;
    if (counting_ && ++in_window_ >= counted_ && close_.load(std::memory_order_acquire)) {
      counting_ = false;
      result_ = end_counting();
      const Faults end = thread_faults();
      faults_.minor = end.minor - faults_at_start_.minor;
      faults_.major = end.major - faults_at_start_.major;
      done_.store(true, std::memory_order_release);
    }
  }
  struct Faults {
    long minor = 0, major = 0;
  };
  // Page faults of the cycle thread within the window. Valid once done().
  [[nodiscard]] Faults faults() const noexcept { return faults_; }
  void arm() noexcept { armed_.store(true, std::memory_order_release); }
  // Open-ended window: close it at the next cycle once `counted` cycles are in it.
  void close() noexcept { close_.store(true, std::memory_order_release); }
  // Cycles in the window. Valid once done().
  [[nodiscard]] uint64_t counted() const noexcept { return in_window_; }
  [[nodiscard]] bool done() const noexcept { return done_.load(std::memory_order_acquire); }
  // Valid once done().
  [[nodiscard]] const HeapCounts& result() const noexcept { return result_; }

 private:
  CycleTask& inner_;
  uint64_t counted_, warmup_;
  uint64_t executed_ = 0, in_window_ = 0;
  bool counting_ = false;
  std::atomic<bool> armed_;
  std::atomic<bool> close_;
  std::atomic<bool> done_{false};
  HeapCounts result_;
  Faults faults_at_start_, faults_;

  // getrusage is a system call: made at the window's two edges only, outside what it counts.
  static Faults thread_faults() noexcept {
    rusage u{};
    getrusage(RUSAGE_THREAD, &u);
    return {u.ru_minflt, u.ru_majflt};
  }
};

struct CycleTraffic {
  uint64_t sent = 0, replies = 0, acks = 0, registers = 0, register_results = 0;
  uint32_t tag = 1;

  // `command`: an encoded EnDat request; `ack_axis`/`register_axis`: where the acknowledgement
  // and the register read go.
  void round(CycleWork& work, BusDriver& bus, std::size_t axes,
             const endat::RequestMessage& command, uint16_t ack_axis, uint16_t register_axis) {
    for (std::size_t axis = 0; axis < axes; ++axis) {
      TunnelRequest r;
      r.tag = tag++;
      r.size = command.size;
      std::copy_n(command.bytes.begin(), command.size, r.bytes.begin());
      if (work.submit_tunnel(axis, r)) ++sent;
      while (auto e = work.poll_tunnel(axis)) replies += e->kind == TunnelEvent::Kind::Received;
    }
    if (work.post({AxisCommand::Kind::AckErrors, ack_axis, 0x10})) ++acks;
    if (bus.submit({tag++, register_axis, reg::kEnDatMode, 1, false, 0})) ++registers;
    RegisterResult rr;
    while (bus.poll(rr)) register_results += !rr.error;
  }
};

}  // namespace ds1928::test
