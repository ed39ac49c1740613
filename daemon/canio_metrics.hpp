// The CAN-I/O bus' metric families (OpenMetrics endpoint): frames, controller state, bus-off,
// the planned cyclic bus load, per node samples (complete, half, missing, late) and SDO figures.
#pragma once

#include "canio/canio_bus.hpp"
#include "metrics/exposition.hpp"

namespace ds1928 {

// Normal thread: reads the bus' atomics and its port counters, like `status`.
void append_canio_metrics(metrics::Exposition& out, const canio::CanioBus& bus);

}  // namespace ds1928
