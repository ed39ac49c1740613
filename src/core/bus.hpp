// The per-cycle interface every bus (simulated, POWERLINK, CAN-I/O) offers the cycle engine.
#pragma once

#include <atomic>
#include <cstdint>
#include <span>
#include <string_view>
#include <system_error>

#include "core/incident.hpp"
#include "core/register_path.hpp"
#include "x20ds1928/module_image.hpp"

namespace ds1928 {

// Where a sample's time stamp comes from.
enum class TimeSource : uint8_t {
  None = 0,         // no stamp (inputs not fresh)
  NetTime = 1,      // module's PosTime (NetTime µs), mapped to CLOCK_MONOTONIC
  RxTimestamp = 2,  // master's reception time of the frame (CAN-I/O, function model 254)
};

// One axis' slot in the cycle: the cycle stages outputs, the exchange fills inputs.
struct AxisIo {
  ModuleOutputs outputs;      // sent during this cycle's exchange
  ModuleInputs inputs;        // valid when inputs_fresh
  bool inputs_fresh = false;  // this cycle's exchange delivered the module's inputs
  int64_t rx_time_ns = 0;     // CLOCK_MONOTONIC reception time of the inputs
  // The axis' own part of the bus is up (its node answers and is configured). False makes only
  // this axis BusDown while the others keep cycling (CAN-I/O: one node being configured).
  bool axis_up = true;
  // The additional-information channels (ModuleInputs::info_ok/info). A bus whose image carries
  // them (simulated, a POWERLINK mapping) leaves info_acyclic false: every fresh input is a read.
  // One that reads them acyclically (CAN-I/O by SDO) sets info_acyclic, and info_fresh in the
  // cycle that brings a completed read (inputs.info_ok/info then hold it, whatever inputs_fresh).
  bool info_acyclic = false;
  bool info_fresh = false;
};

// The bus' NetTime at a reference instant. A module's 32-bit PosTime is unwrapped against it:
// the stamp lies within ±35 min of the reference, so (int32)(stamp - low32(net_time_us)) is
// the offset in µs.
struct NetTimeRef {
  uint64_t net_time_us = 0;  // NetTime at the reference, µs, never wraps
  int64_t monotonic_ns = 0;  // the same instant on CLOCK_MONOTONIC
  bool valid = false;
};

// What one exchange did, for statistics and the axis states.
struct ExchangeResult {
  NetTimeRef net_time;
  bool bus_up = false;       // the bus is cycling (POWERLINK: MN operational for this CN set)
  uint32_t frames_lost = 0;  // expected responses that did not arrive in this cycle
};

enum class BusState : uint8_t { Down = 0, Booting = 1, Operational = 2, Error = 3 };

[[nodiscard]] constexpr std::string_view to_string(BusState s) noexcept {
  switch (s) {
    case BusState::Down:
      return "down";
    case BusState::Booting:
      return "booting";
    case BusState::Operational:
      return "operational";
    case BusState::Error:
      return "error";
  }
  return "?";
}

class BusDriver {
 public:
  virtual ~BusDriver() = default;
  [[nodiscard]] virtual std::string_view name() const noexcept = 0;

  // Normal thread, before the cycle thread starts: open sockets, apply power-up defaults.
  [[nodiscard]] virtual std::error_code start() = 0;
  // Normal thread, after the cycle thread stopped.
  virtual void stop() noexcept = 0;

  // Cycle thread, once per cycle: send every axis' staged outputs, collect inputs within the
  // cycle budget. `cycle_start_ns` is the nominal start on CLOCK_MONOTONIC. Never allocates,
  // never blocks beyond its own receive timeouts, never throws.
  virtual ExchangeResult exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                                  uint64_t cycle_index) noexcept = 0;

  // Any thread.
  [[nodiscard]] virtual BusState state() const noexcept = 0;

  // Acyclic register access (configuration, identification, EnDatAck), normal thread: through
  // the bus' RegisterPath (core/register_path.hpp), which hands the requests to the driver on
  // the cycle thread. False when kRegisterQueueDepth requests wait already. Virtual only for
  // test decorators that wrap another driver.
  [[nodiscard]] virtual bool submit(const RegisterRequest& request) noexcept {
    return !registers_.submit(request);
  }
  // Normal thread. True and fills `out` when a result is ready.
  [[nodiscard]] virtual bool poll(RegisterResult& out) noexcept { return registers_.poll(out); }

  // Normal thread, before the cycle thread starts: where raise_incident() goes (the daemon's
  // flight recorder, core/incident.hpp). nullptr: incidents are not recorded.
  void set_incident_sink(IncidentSink* sink) noexcept { incident_sink_ = sink; }

 protected:
  // Cycle thread: the driver serves the queued register requests through it (RegisterTarget).
  [[nodiscard]] RegisterPath& registers() noexcept { return registers_; }

  // Cycle thread: an incident this driver saw (bus-off, a node's boot-up, a missed heartbeat...).
  // Lock-free, no allocation; a no-op without a sink.
  void raise_incident(IncidentKind kind, int node = -1, int axis = -1,
                      int64_t time_ns = 0) noexcept {
    if (incident_sink_ != nullptr) incident_sink_->raise(kind, node, axis, time_ns);
  }

 private:
  IncidentSink* incident_sink_ = nullptr;
  RegisterPath registers_;
};

}  // namespace ds1928
