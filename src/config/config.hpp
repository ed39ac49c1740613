// The daemon's configuration as plain values with the datasheet's defaults. Loaded from one YAML
// file by load_config(); every field here is documented in docs/configuration.md.
//
// Each part declares what it is told in its own folder (CycleConfig and AxisConfig in core/, the
// bus drivers' options in powerlink/, canio/ and sim/, ShmConfig in shm/, SocketConfig in
// control/); this file only gathers them. Nothing below src/config includes it: the include
// graph points from the configuration down to the parts, never back (tests/layering).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "canio/canio_options.hpp"
#include "control/socket_config.hpp"
#include "core/axis_config.hpp"
#include "core/cycle_config.hpp"
#include "powerlink/powerlink_options.hpp"
#include "shm/shm_config.hpp"
#include "sim/sim_options.hpp"

namespace ds1928 {

enum class BusKind : uint8_t { Simulated, Powerlink, Canio };

// The OpenMetrics endpoint (docs/operations.md "Metrics"). Localhost by default: the figures
// describe the machine, and the endpoint has no authentication of its own.
struct MetricsListen {
  std::string address;  // IPv4 or IPv6 literal
  uint16_t port = 0;    // 0: any free port (tests)
};
struct MetricsConfig {
  std::optional<MetricsListen> listen = MetricsListen{"127.0.0.1", 9928};  // nullopt: off
  uint32_t max_connections = 64;
  uint32_t timeout_ms = 5000;  // to receive a request, and again to send the response
};

// `ds1928ctl capture` (docs/operations.md): the fixed ring each captured link/port gets at start,
// and the limits of one capture.
struct CaptureConfig {
  uint32_t ring_frames = 4096;             // frames per link/port, power of two
  uint32_t max_duration_s = 3600;          // a capture ends after this long at the latest
  uint64_t max_bytes = 1024ULL * 1048576;  // ... or once this many bytes were written
};

// The flight recorder (docs/operations.md "Flight recorder"): an always-on ring of the frames the
// capture points see, written around each incident to a pcapng file in `dir`.
struct FlightRecorderConfig {
  bool enabled = true;
  uint64_t ring_bytes = 1048576;  // all capture points together (split evenly)
  uint32_t before_s = 10;         // the window kept before the event (at most what fits)
  uint32_t after_ms = 500;        // the tail after it
  // "" : $STATE_DIRECTORY/incidents under systemd (StateDirectory=ds1928d: /var/lib/ds1928d/
  // incidents); without systemd no files are written unless a directory is given.
  std::string dir;
  uint32_t max_files = 100;                     // oldest removed first
  uint64_t max_total_bytes = 256ULL * 1048576;  // all files together, oldest removed first
  uint32_t overrun_burst = 10;  // overruns within one second that make an incident (0: never)
};

// What a difference between the expected topology (axes[].expected_encoder, powerlink.nodes[]
// identity) and the bus does (docs/operations.md "Expected topology").
struct TopologyConfig {
  bool refuse = true;  // on_mismatch: refuse (the axis stays bus_down) | warn (logged only)
};

struct DaemonConfig {
  std::string source_file;  // where it was loaded from (for messages)
  CycleConfig cycle;
  BusKind bus = BusKind::Simulated;
  SimulatedBusConfig simulated;
  PowerlinkBusConfig powerlink;
  CanioBusConfig canio;
  std::vector<AxisConfig> axes;
  ShmConfig shm;
  SocketConfig socket;
  MetricsConfig metrics;
  CaptureConfig capture;
  FlightRecorderConfig flight_recorder;
  TopologyConfig topology;
  std::string log_level = "info";
};

}  // namespace ds1928
