// What the simulated node is told about each simulated axis: its motion and its encoder. The
// configuration's `simulated:` section fills it (src/config).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace ds1928 {

enum class MotionProfile : uint8_t { ConstantVelocity, Sine, Stop };

// Simulated node (also the test peer): motion and encoder of each simulated axis.
struct SimAxisConfig {
  MotionProfile profile = MotionProfile::ConstantVelocity;
  double velocity_periods_per_s = 100.0;  // constant velocity
  double amplitude_periods = 1000.0;      // sine
  double frequency_hz = 0.5;              // sine
  uint32_t module_cycle_us = 100;         // the module's system tick (X2X cycle)
  std::string encoder_file;               // optional YAML description of the encoder memory
  uint8_t inject_error_info = 0;          // ErrorInfo bits present from power-up
};
struct SimulatedBusConfig {
  std::vector<SimAxisConfig> axes;  // one per configured axis; missing entries take defaults
};

}  // namespace ds1928
