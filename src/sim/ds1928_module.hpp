// Simulated X20DS1928: the module's register set (function model 0 and 254) with an encoder
// following a motion profile. Time-driven and single-threaded: the owner calls tick() at the
// module's system tick and exchanges the cyclic image; no clocks or threads inside.
#pragma once

#include <cstdint>
#include <memory>
#include <system_error>

#include "flatstream/channel.hpp"
#include "sim/encoder_description_yaml.hpp"
#include "sim/endat_bridge.hpp"
#include "sim/sim_options.hpp"
#include "x20ds1928/module_image.hpp"
#include "x20ds1928/module_settings.hpp"

namespace ds1928::sim {

class Ds1928Module {
 public:
  // The encoder behind the module: `encoder` (default: the built-in multiturn rotary encoder;
  // SimAxisConfig::encoder_file is loaded by the owner, see load_encoder()).
  Ds1928Module(FunctionModel model, const SimAxisConfig& sim,
               EncoderDescription encoder = default_encoder_description());
  ~Ds1928Module();
  Ds1928Module(const Ds1928Module&) = delete;
  Ds1928Module& operator=(const Ds1928Module&) = delete;

  // Power-up: every acyclic register takes its bus-controller default (EnDat disabled).
  void power_up() noexcept;

  // Advance the module to `monotonic_ns`; `net_time_us` is the NetTime at that instant. Runs the
  // EnDat cycle (module cycle × prescaler), stamps PosTime, steps the Flatstream module channel.
  void tick(int64_t monotonic_ns, uint64_t net_time_us) noexcept;

  // Cyclic image as the bus carries it.
  void apply_outputs(const ModuleOutputs& outputs) noexcept;
  [[nodiscard]] ModuleInputs inputs() const noexcept;

  // Acyclic registers (configuration, identification, EnDatAck). `size` in bytes: 1, 2 or 4.
  [[nodiscard]] std::error_code write_register(uint16_t reg, uint8_t size, uint32_t value) noexcept;
  [[nodiscard]] std::error_code read_register(uint16_t reg, uint8_t size,
                                              uint32_t& value) const noexcept;

  // Fault injection: ErrorInfo bits that appear now and stay until acknowledged (AckErrorInfo).
  void inject_error(uint8_t error_info_bits) noexcept;
  // The sin/cos track's peak-to-peak amplitude in mV (1000 at power-up, a healthy encoder). With
  // the track in use, outside SinCosVssMin..SinCosVssMax the module sets VssCheckError (while
  // ErrorEnable bit 2 allows it) and keeps the last good position: no new position, PosCycle
  // stands. Back inside the window it ignores good values for SinCosQuitTime before it takes
  // positions again (§11.7.4–11.7.6).
  void set_vss_mv(uint32_t millivolts) noexcept;
  // The encoder supply as the module measures it in mV (5000 at power-up). Below 4750 (the
  // datasheet's 5 V −5 %) the module sets EncoderSupplyError (while ErrorEnable bit 0 allows it)
  // and takes no position from the underpowered encoder: PosCycle stands until it is back.
  void set_supply_mv(uint32_t millivolts) noexcept;
  // The encoder's error and warning words are set through endat().encoder()
  // (set_error_conditions / set_warning_conditions); SimAxisConfig's faults are applied through
  // the same calls.

  [[nodiscard]] FunctionModel function_model() const noexcept;

  // Views for tests and status of the simulator.
  [[nodiscard]] const flatstream::ModuleChannel& flatstream() const noexcept;
  [[nodiscard]] EnDatBridge& endat() noexcept;

 private:
  void run_flatstream(int64_t now_ns) noexcept;
  void update_error_info() noexcept;
  void serve_info_channels() noexcept;
  void apply_configured_faults() noexcept;
  struct State;
  std::unique_ptr<State> state_;
};

// The encoder description a simulated axis asks for: the built-in one, or its encoder_file.
[[nodiscard]] EncoderLoadResult load_encoder(const SimAxisConfig& sim);

// Applies a configured axis' ModuleSettings through write_register (what a master does at boot).
[[nodiscard]] std::error_code configure_module(Ds1928Module& module,
                                               const ModuleSettings& settings);

}  // namespace ds1928::sim
