// The normal thread's side of the allocation proofs: one round of the traffic a running daemon
// puts through its cycle work — an EnDat command into every axis' Flatstream tunnel, replies
// collected, an error acknowledgement, an acyclic register read — counted so the proofs can
// require that it really went through the counted cycles.
#pragma once

#include <algorithm>
#include <cstdint>

#include "core/bus.hpp"
#include "cycle_work.hpp"
#include "endat/command.hpp"

namespace ds1928::test {

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
