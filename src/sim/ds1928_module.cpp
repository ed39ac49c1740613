#include "sim/ds1928_module.hpp"

#include <cmath>
#include <numbers>

#include "sim/sim_error.hpp"
#include "x20ds1928/info_channels.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::sim {

namespace {

// The acyclic registers the simulated module keeps: the configuration a master writes at start
// (every object-dictionary entry with a setting) and the self-clearing commands (EnDatAck, which
// reads back 0). The EnDatInfo channels are kept apart (State::info_cmd, ModuleInputs::info);
// identification and status words come from the EnDat bridge.
[[nodiscard]] constexpr bool kept(const RegisterInfo& r) noexcept {
  return !r.view && r.count == 1 &&
         (r.setting != Setting::None || r.direction == RegisterDirection::Command);
}

// Values by object-dictionary position (only kept() entries are used).
class Registers {
 public:
  // Power-up: the bus-controller defaults of the object dictionary (EnDatMode = 0: the encoder
  // interface starts disabled, so a master that configures nothing reads nothing). Registers
  // without a datasheet default (OutputMTU, InputMTU): under function model 254 they power up
  // unset (0) — "bei der Minimalkonfiguration müssen InputMTU und OutputMTU eingestellt werden"
  // (§11.9.4.1) — and the Flatstream is idle until both are written; under function model 0 the
  // bus controller has already configured them with the settings' defaults.
  static Registers power_up(FunctionModel model) noexcept {
    Registers g;
    for (const RegisterInfo& r : kObjectDictionary) {
      if (!kept(r)) continue;
      g.values_[od_index(r)] = r.default_value.value_or(
          model == FunctionModel::BusController ? 0 : setting_value(r.setting, ModuleSettings{}));
    }
    return g;
  }
  [[nodiscard]] uint32_t operator[](uint16_t reg) const noexcept {
    const RegisterInfo* r = find_register(reg);
    return r ? values_[od_index(*r)] : 0;
  }
  void set(const RegisterInfo& r, uint32_t v) noexcept { values_[od_index(r)] = v; }

 private:
  std::array<uint32_t, kObjectDictionary.size()> values_{};
};

}  // namespace

[[nodiscard]] flatstream::ModuleConfig channel_config(const Registers& r) noexcept {
  flatstream::ModuleConfig c;
  // An unset MTU (0, function model 254 at power-up) idles the Flatstream (run_flatstream); the
  // channel itself keeps the smallest valid size meanwhile.
  const auto mtu = [&](uint16_t reg) {
    const auto v = static_cast<uint8_t>(r[reg]);
    return v == 0 ? uint8_t{3} : v;
  };
  c.output_mtu = mtu(reg::kOutputMtu);
  c.input_mtu = mtu(reg::kInputMtu);
  c.flatstream_mode = static_cast<uint8_t>(r[reg::kFlatstreamMode]);
  c.forward = static_cast<uint8_t>(r[reg::kForward]);
  c.forward_delay_us = static_cast<uint16_t>(r[reg::kForwardDelay]);
  return c;
}

struct Ds1928Module::State {
  explicit State(EncoderDescription encoder)
      : steps_per_period(encoder.signal_periods == 0
                             ? 1.0
                             : static_cast<double>(encoder.steps_per_revolution) /
                                   encoder.signal_periods),
        channel(channel_config(Registers::power_up(FunctionModel::Standard))),
        bridge(EnDatEncoder(std::move(encoder))) {}
  double steps_per_period;  // the encoder's measuring steps per sine period
  FunctionModel model;
  SimAxisConfig sim;
  Registers regs;
  ModuleInputs in;
  ModuleOutputs out;
  uint8_t latched_errors = 0;   // present until acknowledged
  uint32_t vss_mv = 1000;       // sin/cos amplitude (set_vss_mv)
  uint32_t supply_mv = 5000;    // encoder supply (set_supply_mv)
  bool faults_applied = false;  // SimAxisConfig's faults are in place
  int64_t faults_at_ns = 0;     // when they appear (module time)
  bool vss_bad = false;         // the last EnDat cycle saw the amplitude outside the window
  int64_t vss_good_from_ns = INT64_MIN;  // end of SinCosQuitTime after the window was left
  uint8_t prev_ack = 0;                  // AckErrorInfo acts on rising edges
  std::array<uint32_t, kInfoChannels> info_cmd{};  // EnDatInfoCmd01..04 (0 at power-up)
  bool started = false;
  int64_t origin_ns = 0;     // motion profile time zero
  int64_t next_tick_ns = 0;  // next module system tick
  uint64_t ticks = 0;        // module system ticks since power-up
  int64_t now_ns = 0;        // time of the last tick
  // Flatstream: stepped once per bus cycle (when the master's outputs arrive), not per tick —
  // the protocol counts bus cycles.
  flatstream::ModuleChannel channel;
  bool outputs_pending = false;
  std::optional<flatstream::Message> command;  // received, waiting for the EnDat channel
  EnDatBridge bridge;
  uint32_t reply_tag = 0;
};

Ds1928Module::Ds1928Module(FunctionModel model, const SimAxisConfig& sim,
                           EncoderDescription encoder)
    : state_(std::make_unique<State>(std::move(encoder))) {
  state_->model = model;
  state_->sim = sim;
  if (state_->sim.module_cycle_us == 0) state_->sim.module_cycle_us = 100;
  power_up();
}

Ds1928Module::~Ds1928Module() = default;

FunctionModel Ds1928Module::function_model() const noexcept {
  return state_->model;
}

void Ds1928Module::power_up() noexcept {
  State& s = *state_;
  s.regs = Registers::power_up(s.model);
  s.in = ModuleInputs{};
  s.out = ModuleOutputs{};
  s.latched_errors = 0;
  s.faults_applied = false;
  if (s.sim.faults_after_ms == 0) apply_configured_faults();
  s.vss_bad = false;
  s.vss_good_from_ns = INT64_MIN;
  s.prev_ack = 0;
  s.info_cmd = {};
  s.started = false;
  s.ticks = 0;
  s.channel.configure(channel_config(s.regs));
  s.channel.reset();
  s.outputs_pending = false;
  s.command.reset();
  if ((s.regs[reg::kEnDatMode] & endat_mode::kEnable) == 0 &&
      s.model == FunctionModel::BusController)
    s.bridge.power_up_unread();  // EnDat disabled: the encoder is not read until a Rescan
  else
    (void)s.bridge.power_up(s.now_ns);  // a failed identification shows as EnDatParSetError
}

const flatstream::ModuleChannel& Ds1928Module::flatstream() const noexcept {
  return state_->channel;
}
EnDatBridge& Ds1928Module::endat() noexcept {
  return state_->bridge;
}

EncoderLoadResult load_encoder(const SimAxisConfig& sim) {
  if (sim.encoder_file.empty()) return {default_encoder_description(), {}};
  return load_encoder_description(sim.encoder_file);
}

void Ds1928Module::inject_error(uint8_t bits) noexcept {
  state_->latched_errors |= bits;
}

void Ds1928Module::set_vss_mv(uint32_t millivolts) noexcept {
  state_->vss_mv = millivolts;
}

void Ds1928Module::set_supply_mv(uint32_t millivolts) noexcept {
  state_->supply_mv = millivolts;
}

// SimAxisConfig's faults, through the same calls a test makes.
void Ds1928Module::apply_configured_faults() noexcept {
  State& s = *state_;
  s.faults_applied = true;
  s.latched_errors |= s.sim.inject_error_info;
  if (s.sim.endat_error != 0) s.bridge.encoder().set_error_conditions(s.sim.endat_error);
  if (s.sim.endat_warning != 0) s.bridge.encoder().set_warning_conditions(s.sim.endat_warning);
  if (s.sim.vss_mv != 1000) s.vss_mv = s.sim.vss_mv;
  if (s.sim.supply_mv != 5000) s.supply_mv = s.sim.supply_mv;
}

namespace {

constexpr uint32_t kSupplyMinMv = 4750;

[[nodiscard]] double profile_position(const SimAxisConfig& sim, double t_s) noexcept {
  switch (sim.profile) {
    case MotionProfile::ConstantVelocity:
      return sim.velocity_periods_per_s * t_s;
    case MotionProfile::Sine:
      return sim.amplitude_periods * std::sin(2.0 * std::numbers::pi * sim.frequency_hz * t_s);
    case MotionProfile::Stop:
      return 0.0;
  }
  return 0.0;
}

// Sin/cos fixed point: bits 63..16 whole periods, bits 15..0 fraction with 13-bit resolution
// (the low 3 bits are always 0). Two's complement carries negative positions.
[[nodiscard]] uint64_t to_fixed_point(double periods) noexcept {
  const auto scaled = static_cast<int64_t>(std::floor(periods * 65536.0));
  return static_cast<uint64_t>(scaled) & ~uint64_t{7};
}

// The sin/cos track off (EnDatMode bit 3): the 64 bits carry the EnDat position itself, one count
// per measuring step (§11.5.2 "the absolute position of the encoder in 64 bits"; the datasheet
// draws no layout for this case). Strict reading, docs/registers.md §Position formats: the
// encoder's `bits`-bit value right-aligned, zero-extended — or, in the signed format (EnDatMode
// bit 1), sign-extended from its top bit.
[[nodiscard]] uint64_t to_endat_position(uint64_t steps, unsigned bits, bool is_signed) noexcept {
  if (bits == 0 || bits >= 64) return steps;
  const uint64_t mask = (uint64_t{1} << bits) - 1;
  steps &= mask;
  if (is_signed && (steps >> (bits - 1)) != 0) steps |= ~mask;
  return steps;
}

}  // namespace

void Ds1928Module::tick(int64_t monotonic_ns, uint64_t net_time_us) noexcept {
  State& s = *state_;
  const int64_t tick_ns = int64_t{s.sim.module_cycle_us} * 1000;
  if (!s.started) {
    s.started = true;
    s.origin_ns = monotonic_ns;
    s.next_tick_ns = monotonic_ns;
    s.faults_at_ns = monotonic_ns + int64_t{s.sim.faults_after_ms} * 1'000'000;
  }
  if (!s.faults_applied && monotonic_ns >= s.faults_at_ns) apply_configured_faults();
  // Catch up every system tick up to now; a long gap (power-cycled bus, stopped debugger) does
  // not replay thousands of ticks: at most one EnDat cycle's worth matters.
  if (monotonic_ns - s.next_tick_ns > 64 * tick_ns) {
    const int64_t skip = (monotonic_ns - s.next_tick_ns) / tick_ns - 64;
    s.next_tick_ns += skip * tick_ns;
    s.ticks += static_cast<uint64_t>(skip);
  }
  while (s.next_tick_ns <= monotonic_ns) {
    const int64_t at_ns = s.next_tick_ns;
    s.next_tick_ns += tick_ns;
    ++s.ticks;
    if (s.model == FunctionModel::Standard)
      s.in.sdc_life_count = static_cast<int8_t>(s.in.sdc_life_count + 1);
    const uint32_t prescaler =
        s.regs[reg::kSystemCyclePrescaler] == 0 ? 1 : s.regs[reg::kSystemCyclePrescaler];
    if (s.ticks % prescaler != 0) continue;
    // The encoder supply (5 V ±5 %, §3 technical data; the datasheet gives no trip point, the
    // strict reading takes the tolerance's lower end): an underpowered encoder's position is not
    // taken, whether or not the error is reported.
    if (s.supply_mv < kSupplyMinMv) {
      if ((s.regs[reg::kErrorEnable] & error_info::kEncoderSupplyError) != 0)
        s.latched_errors |= error_info::kEncoderSupplyError;
      continue;
    }
    // One EnDat cycle: acquire a position when the interface is enabled.
    if ((s.regs[reg::kEnDatMode] & endat_mode::kEnable) == 0) continue;
    const uint8_t mode = static_cast<uint8_t>(s.regs[reg::kEnDatMode]);
    if ((mode & endat_mode::kSinCosUnused) == 0 &&
        (s.regs[reg::kErrorEnable] & error_info::kVssCheckError) != 0) {
      // §11.7.6: after an error on the analogue interface the last good values stay; good
      // values count again only SinCosQuitTime after the error.
      if (s.vss_mv < s.regs[reg::kSinCosVssMin] || s.vss_mv > s.regs[reg::kSinCosVssMax]) {
        s.vss_bad = true;
        s.latched_errors |= error_info::kVssCheckError;
        continue;
      }
      if (s.vss_bad) {
        s.vss_bad = false;
        s.vss_good_from_ns = at_ns + int64_t{s.regs[reg::kSinCosQuitTime]} * 1000;
      }
      if (at_ns < s.vss_good_from_ns) continue;
    }
    const double t_s = static_cast<double>(at_ns - s.origin_ns) * 1e-9;
    const double periods = profile_position(s.sim, t_s);
    // The absolute position comes over the EnDat wire (position frame with CRC); a frame that
    // fails leaves the last good position in place and no new PosCycle, as the module does.
    s.bridge.set_position(
        static_cast<uint64_t>(static_cast<int64_t>(periods * s.steps_per_period)));
    const PositionReading reading = s.bridge.read_position(at_ns);
    if (reading.error) continue;
    const uint64_t raw = (mode & endat_mode::kSinCosUnused) == 0
                             ? to_fixed_point(periods)
                             : to_endat_position(reading.steps, s.bridge.position_bits(),
                                                 (mode & endat_mode::kSigned) != 0);
    s.in.position_hw = static_cast<uint32_t>(raw >> 32);
    s.in.position_lw = static_cast<uint32_t>(raw);
    // PosTime = NetTime of the acquisition instant (µs).
    const int64_t behind_us = (monotonic_ns - at_ns) / 1000;
    if (s.model == FunctionModel::Standard)
      s.in.pos_time_us = static_cast<uint32_t>(net_time_us - static_cast<uint64_t>(behind_us));
    s.in.pos_cycle = static_cast<int8_t>(s.in.pos_cycle + 1);
    serve_info_channels();
  }
  s.now_ns = monotonic_ns;
  run_flatstream(monotonic_ns);
  update_error_info();
}

// §11.8.3: the four channels are served with the position frames of each EnDat cycle. The
// simulator takes each channel's word from the encoder's model directly (the wire carries the
// position; the additional information's frames are the bridge's to test); a request the encoder
// cannot answer — an EnDat 2.2 read of a 2.1 encoder, a parameter it lacks — leaves the channel's
// EnDatInfoOK bit 0, as does a channel left off.
void Ds1928Module::serve_info_channels() noexcept {
  State& s = *state_;
  const EnDatEncoder& enc = s.bridge.encoder();
  uint8_t ok = 0;
  for (std::size_t i = 0; i < kInfoChannels; ++i) {
    if (s.info_cmd[i] == 0) continue;
    const InfoRequest r = decode_info_command(s.info_cmd[i]);
    if (!info_request_problem(r).empty()) continue;
    std::optional<uint16_t> word;
    if (r.command >= info_command::kReadInfoWord1) {
      if (enc.command_set() == endat::CommandSet::EnDat22) word = enc.additional_info(r.mrs);
    } else {
      word = enc.word(r.mrs, r.block.value_or(0), r.parameter);
    }
    if (!word) continue;
    s.in.info[i] = *word;
    ok = static_cast<uint8_t>(ok | (1u << i));
  }
  s.in.info_ok = ok;
}

void Ds1928Module::update_error_info() noexcept {
  State& s = *state_;
  const uint8_t present = static_cast<uint8_t>(s.latched_errors | s.bridge.error_info());
  s.in.error_info = static_cast<uint8_t>(present & s.regs[reg::kErrorEnable] & ~0x02);
}

void Ds1928Module::run_flatstream(int64_t now_ns) noexcept {
  State& s = *state_;
  // EnDat side: a finished reply goes into the input direction, a waiting command to the encoder.
  // Outcomes of sent replies are not needed here, but they share the send queue's capacity.
  while (s.channel.take_outcome()) {
  }
  if (auto reply = s.bridge.poll(now_ns)) {
    (void)s.channel.submit(reply->bytes(), ++s.reply_tag);  // queue_full: the master is gone
  }
  if (s.command && s.bridge.submit(s.command->payload(), now_ns)) s.command.reset();
  if (!s.outputs_pending) return;
  s.outputs_pending = false;
  if (s.regs[reg::kOutputMtu] == 0 || s.regs[reg::kInputMtu] == 0) return;  // MTUs not set yet
  const auto frame =
      s.channel.step(flatstream::output_frame(s.out), static_cast<uint64_t>(now_ns / 1000));
  flatstream::apply(frame, s.in);
  if (!s.command) {
    if (auto m = s.channel.take_received()) s.command = *m;
  }
}

void Ds1928Module::apply_outputs(const ModuleOutputs& outputs) noexcept {
  State& s = *state_;
  s.out = outputs;
  s.outputs_pending = true;
  const uint8_t rising = static_cast<uint8_t>(outputs.ack_error_info & ~s.prev_ack);
  s.prev_ack = outputs.ack_error_info;
  s.latched_errors = static_cast<uint8_t>(s.latched_errors & ~rising);
  if (rising != 0) s.bridge.acknowledge_error_info(rising);
  update_error_info();
}

ModuleInputs Ds1928Module::inputs() const noexcept {
  return state_->in;
}

std::error_code Ds1928Module::write_register(uint16_t reg, uint8_t size, uint32_t v) noexcept {
  State& s = *state_;
  const RegisterInfo* r = find_register(reg);
  if (r && r->contains(reg::kEnDatInfoCmd01) && r->in_model(s.model)) {
    if (size != r->size()) return make_error_code(SimErrc::wrong_size);
    s.info_cmd[r->member(reg)] = v;
    s.in.info_ok = static_cast<uint8_t>(s.in.info_ok & ~(1u << r->member(reg)));
    return {};
  }
  if (!r || !kept(*r) || !r->in_model(s.model)) {
    uint32_t ignored = 0;
    if (!read_register(reg, size, ignored)) return make_error_code(SimErrc::read_only);
    return make_error_code(SimErrc::unknown_register);
  }
  if (size != r->size()) return make_error_code(SimErrc::wrong_size);
  if (!r->accepts(s.model).contains(v)) return make_error_code(SimErrc::out_of_range);
  if (r->direction == RegisterDirection::Command) {
    s.bridge.endat_ack(static_cast<uint8_t>(v), s.now_ns);  // EnDatAck: self-clearing
    return {};
  }
  s.regs.set(*r, v);
  if (is_flatstream_setting(r->setting)) s.channel.configure(channel_config(s.regs));
  return {};
}

std::error_code Ds1928Module::read_register(uint16_t reg, uint8_t size,
                                            uint32_t& v) const noexcept {
  const State& s = *state_;
  if (const RegisterInfo* r = find_register(reg); r && kept(*r) && r->in_model(s.model)) {
    if (size != r->size()) return make_error_code(SimErrc::wrong_size);
    v = r->direction == RegisterDirection::Command ? s.bridge.endat_ack_pending(s.now_ns)
                                                   : s.regs[reg];
    return {};
  }
  if (const RegisterInfo* r = find_register(reg); r && r->in_model(s.model)) {
    if (r->contains(reg::kEnDatInfoCmd01)) {
      if (size != r->size()) return make_error_code(SimErrc::wrong_size);
      v = s.info_cmd[r->member(reg)];
      return {};
    }
    if (r->contains(reg::kEnDatInfoOk)) {
      if (size != r->size()) return make_error_code(SimErrc::wrong_size);
      v = s.in.info_ok;
      return {};
    }
    if (r->contains(reg::kEnDatInfo01)) {
      if (size != r->size()) return make_error_code(SimErrc::wrong_size);
      v = s.in.info[r->member(reg)];
      return {};
    }
  }
  // Identification, EnDatError/EnDatWarning: the encoder's words (UINT).
  if (auto word = s.bridge.read_register(reg)) {
    if (size != 2) return make_error_code(SimErrc::wrong_size);
    v = *word;
    return {};
  }
  return make_error_code(SimErrc::unknown_register);
}

std::error_code configure_module(Ds1928Module& m, const ModuleSettings& s) {
  for (const RegisterWrite& w : startup_writes(s)) {
    if (auto ec = m.write_register(w.reg, w.size, w.value)) return ec;
  }
  // Named first: a range-for over .span() of a temporary would read it after its end.
  const InfoCommandWrites info = info_command_writes(s);
  for (const RegisterWrite& w : info.span()) {
    if (auto ec = m.write_register(w.reg, w.size, w.value)) return ec;
  }
  // Function model 254 boots with EnDat disabled and the identification unread: after enabling
  // it, Rescan (EnDatAck bit 1) as the CAN-I/O driver does.
  if (m.function_model() == FunctionModel::BusController && s.endat_enable)
    return m.write_register(reg::kEnDatAck, 1, 0x02);
  return {};
}

}  // namespace ds1928::sim
