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
  // Faults of the module and its encoder (docs/configuration.md §simulated): they appear
  // faults_after_ms after power-up (module time; 0 = at power-up) and stay.
  uint8_t inject_error_info = 0;  // ErrorInfo bits, latched until acknowledged (AckErrorInfo)
  uint16_t endat_error = 0;       // the encoder's error conditions (EnDatError bits)
  uint16_t endat_warning = 0;     // the encoder's warning conditions (EnDatWarning bits)
  uint32_t vss_mv = 1000;         // sin/cos amplitude, peak to peak (a healthy 1 Vpp track)
  uint32_t supply_mv = 5000;      // encoder supply as the module measures it
  uint32_t faults_after_ms = 0;
};
struct SimulatedBusConfig {
  std::vector<SimAxisConfig> axes;  // one per configured axis; missing entries take defaults
};

}  // namespace ds1928
