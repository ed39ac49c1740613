// What the virtual CAN bus tests (instant and timed) share: a fake bus clock, a port that must
// open, draining a port, a real-clock deadline, and the two ends of the forked "node" process
// that talks to the test over a shared bus.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <memory>
#include <string>
#include <vector>

#include "can/virtual_bus.hpp"
#include "core/clock.hpp"

namespace ds1928::canio::test {

inline constexpr int64_t kFakeClockStart = 1'000'000'000;

// The bus clock a test moves by hand; starts at kFakeClockStart.
struct FakeClock {
  std::shared_ptr<std::atomic<int64_t>> now =
      std::make_shared<std::atomic<int64_t>>(kFakeClockStart);
  // `o` on this clock.
  [[nodiscard]] VirtualBusOptions options(VirtualBusOptions o = {}) const {
    auto n = now;
    o.clock = [n] { return n->load(); };
    return o;
  }
  void set(int64_t t) { now->store(t); }
  void advance(int64_t ns) { now->fetch_add(ns); }
  void advance_ms(int64_t ms) { advance(ms * 1'000'000); }
  [[nodiscard]] int64_t get() const { return now->load(); }
};

inline std::unique_ptr<VirtualCanPort> port(const std::shared_ptr<VirtualCanBus>& bus,
                                            VirtualPortOptions o = {}) {
  auto p = bus->open_port(std::move(o));
  REQUIRE(p);
  return std::move(p.value());
}

// Everything queued for `p` right now (non-blocking poll).
inline std::vector<CanFrame> drain(CanPort& p) {
  std::vector<CanFrame> all;
  std::array<CanFrame, 16> buf;
  for (;;) {
    auto r = p.receive(buf, 0);
    REQUIRE_FALSE(r.error);
    if (r.count == 0) return all;
    all.insert(all.end(), buf.begin(), buf.begin() + r.count);
  }
}

// A receive() deadline `seconds` from now on the real clock (a bus without a fake clock).
[[nodiscard]] inline int64_t deadline_in(int64_t seconds) {
  return rt::now_ns() + seconds * rt::kNsPerSec;
}

// The forked node: its port on the shared bus `name`, listening to `listen` only, after it
// announced itself with `ready`. Ends the child with exit code 2..5 naming the step that failed
// (Catch2 must not run in the child).
[[nodiscard]] inline std::unique_ptr<VirtualCanPort> node_port(const std::string& name,
                                                               const VirtualBusOptions& o,
                                                               uint32_t listen,
                                                               const CanFrame& ready) {
  auto b = VirtualCanBus::open_shared(name, o);
  if (!b) _exit(2);
  auto p = (*b)->open_port();
  if (!p) _exit(3);
  const CanIdFilter ids[] = {{listen, false}};
  if ((*p)->set_filters(ids)) _exit(4);
  if (!(*p)->send(ready).sent()) _exit(5);
  return std::move(p.value());
}

// The test's end: the node's `ready` frame arrives before `deadline`.
inline void expect_node_up(CanPort& me, uint32_t ready_id, int64_t deadline) {
  std::array<CanFrame, 8> buf;
  auto r = me.receive(buf, deadline);
  REQUIRE(r.count == 1);
  CHECK(buf[0].id == ready_id);
}

// The forked node ended with exit code 0.
inline void expect_node_done(pid_t child) {
  int status = 0;
  REQUIRE(waitpid(child, &status, 0) == child);
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
}

}  // namespace ds1928::canio::test
