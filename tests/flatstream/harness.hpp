// Test helpers: a scripted peer that speaks the raw registers, and a perfect bus.
#pragma once

#include <cstdint>
#include <vector>

#include "flatstream/channel.hpp"

namespace ds1928::flatstream::test {

using Bytes = std::vector<uint8_t>;

inline Bytes bytes_of(const Message& m) {
  return Bytes(m.payload().begin(), m.payload().end());
}

inline Bytes mtu_prefix(const MtuBytes& mtu, std::size_t n) {
  return Bytes(mtu.begin(), mtu.begin() + static_cast<std::ptrdiff_t>(n));
}

// Master and module joined by a loss-free bus: the module sees this cycle's output frame, the
// master sees the input frame of the previous cycle.
struct PerfectBus {
  MasterChannel& master;
  ModuleChannel& module;
  InputFrame in{};
  OutputFrame out{};
  uint64_t now_us = 0;
  uint32_t cycle_us = 100;

  void cycle() {
    out = master.step(in, now_us);
    in = module.step(out, now_us);
    now_us += cycle_us;
  }
  bool run_until(auto pred, int max_cycles = 10000) {
    for (int i = 0; i < max_cycles; ++i) {
      if (pred()) return true;
      cycle();
    }
    return pred();
  }
};

}  // namespace ds1928::flatstream::test
