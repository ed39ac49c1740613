#include "cycle_work.hpp"

namespace ds1928 {

CycleWork::CycleWork(const DaemonConfig& config, BusDriver& bus, shm::Publisher& publisher)
    : bus_(bus),
      publisher_(publisher),
      io_(config.axes.size()),
      params_(config.axes.size()),
      decode_state_(config.axes.size()),
      status_(config.axes.size()),
      ack_bits_(config.axes.size(), 0),
      ack_hold_(config.axes.size(), 0),
      counters_(std::make_unique<AxisCounters[]>(config.axes.size())) {
  for (std::size_t i = 0; i < config.axes.size(); ++i) {
    params_[i].signed_format = config.axes[i].module.position_signed;
    params_[i].has_pos_time = config.axes[i].function_model == FunctionModel::Standard;
  }
}

void CycleWork::run_cycle(const CycleContext& ctx) noexcept {
  // Requests of the normal thread: at most a queue's worth per cycle, so a flood cannot stretch
  // the cycle.
  for (std::size_t n = 0; n < commands_.capacity(); ++n) {
    auto command = commands_.try_pop();
    if (!command) break;
    if (command->axis >= io_.size()) continue;  // validated by the sender; never trusted here
    if (command->kind == AxisCommand::Kind::AckErrors) {
      ack_bits_[command->axis] |= command->bits;
      ack_hold_[command->axis] = kAckHoldCycles;
    }
  }
  for (std::size_t i = 0; i < io_.size(); ++i) {
    if (ack_hold_[i] > 0) {
      --ack_hold_[i];
    } else {
      ack_bits_[i] = 0;
    }
    io_[i].outputs.ack_error_info = ack_bits_[i];
  }

  const ExchangeResult result = bus_.exchange(io_, ctx.start_ns, ctx.index);
  exchanges_.store(exchanges_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  frames_lost_.store(frames_lost_.load(std::memory_order_relaxed) + result.frames_lost,
                     std::memory_order_relaxed);
  bus_up_.store(result.bus_up, std::memory_order_relaxed);

  bool any_fresh = false;
  for (std::size_t i = 0; i < io_.size(); ++i) {
    const AxisSample sample = decode_axis(io_[i], params_[i], result.net_time, decode_state_[i]);
    AxisCounters& c = counters_[i];
    auto bump = [](std::atomic<uint64_t>& a) {
      a.store(a.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    };
    bump(sample.fresh ? c.fresh_cycles : c.stale_cycles);
    if (sample.new_position) bump(c.new_positions);
    if (sample.fresh && !sample.fraction_valid) bump(c.format_violations);
    c.error_info.store(sample.error_info, std::memory_order_relaxed);
    any_fresh |= sample.fresh;

    shm::AxisStatus& st = status_[i];
    st.sample = sample;
    st.endat_error = c.endat_error.load(std::memory_order_relaxed);
    st.endat_warning = c.endat_warning.load(std::memory_order_relaxed);
    st.validity = shm::classify(sample, result.bus_up);
    // A position that breaks the format is never published as valid.
    if (st.validity == shm::AxisValidity::Valid && !sample.fraction_valid)
      st.validity = shm::AxisValidity::ModuleError;
  }
  if (any_fresh)
    data_exchanges_.store(data_exchanges_.load(std::memory_order_relaxed) + 1,
                          std::memory_order_relaxed);
  publisher_.publish(ctx.index, status_);
}

}  // namespace ds1928
