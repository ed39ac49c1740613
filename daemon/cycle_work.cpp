#include "cycle_work.hpp"

#include <algorithm>

namespace ds1928 {

CycleWork::CycleWork(const DaemonConfig& config, BusDriver& bus, shm::Publisher& publisher)
    : bus_(bus),
      publisher_(publisher),
      io_(config.axes.size()),
      params_(config.axes.size()),
      policies_(config.axes.size()),
      decode_state_(config.axes.size()),
      status_(config.axes.size()),
      ack_bits_(config.axes.size(), 0),
      ack_hold_(config.axes.size(), 0),
      counters_(std::make_unique<AxisCounters[]>(config.axes.size())),
      next_wake_offset_ns_((int64_t{config.cycle.period_us} - int64_t{config.cycle.spin_us}) *
                           1000),
      // Every axis starts bus_down (nothing exchanged yet): that first state is no incident.
      last_validity_(config.axes.size(), static_cast<uint8_t>(shm::AxisValidity::BusDown)),
      overrun_burst_(config.flight_recorder.overrun_burst),
      cycles_per_second_(
          std::max<uint64_t>(1, 1000000 / std::max<uint32_t>(1, config.cycle.period_us))) {
  for (std::size_t i = 0; i < config.axes.size(); ++i) {
    const ModuleSettings& m = config.axes[i].module;
    flatstream::MasterConfig fc;
    fc.output_mtu = m.output_mtu;
    fc.input_mtu = m.input_mtu;
    // Pipelining the output direction is safe only while the module takes a sequence per cycle.
    fc.output_forward = m.forward_delay_us < config.cycle.period_us ? m.forward : uint8_t{1};
    fc.timeout_cycles = config.axes[i].flatstream_timeout_cycles;
    tunnels_.push_back(std::make_unique<Tunnel>(fc));
    params_[i].signed_format = config.axes[i].module.position_signed;
    params_[i].sincos_track = !config.axes[i].module.sincos_unused;
    policies_[i] = config.axes[i].error_policy();
    params_[i].has_pos_time = config.axes[i].function_model == FunctionModel::Standard;
    params_[i].max_stamp_age_ns = default_max_stamp_age_ns(int64_t{config.cycle.period_us} * 1000);
    // Stalled acquisition (repeats of one position go stale after a limit) on the real buses;
    // the built-in simulated bus keeps its injected faults' own semantics.
    if (config.bus == BusKind::Canio || config.bus == BusKind::Powerlink)
      params_[i].stall_limit =
          stall_limit_cycles(config.bus == BusKind::Canio ? config.canio.stall_limit : 0,
                             m.prescaler, config.cycle.period_us);
    const bool expected = config.axes[i].expected_encoder.any();
    counters_[i].identity.store(
        static_cast<uint8_t>(expected ? IdentityState::Pending : IdentityState::Unchecked),
        std::memory_order_relaxed);
    identity_gate_.push_back(expected && config.topology.refuse ? 1 : 0);
    AxisInfo& info = status_[i].info;
    for (std::size_t n = 0; n < config.axes[i].info.size() && n < kInfoChannels; ++n) {
      info.configured = static_cast<uint8_t>(info.configured | 1u << n);
      if (config.axes[i].info[n].is_signed)
        info.is_signed = static_cast<uint8_t>(info.is_signed | 1u << n);
    }
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
  last_cycle_ns_.store(ctx.start_ns, std::memory_order_relaxed);

  bool any_fresh = false;
  for (std::size_t i = 0; i < io_.size(); ++i) {
    AxisSample sample = decode_axis(io_[i], params_[i], result.net_time, decode_state_[i]);
    AxisCounters& c = counters_[i];
    const ErrorWords words{sample.error_info,
                           static_cast<uint16_t>(c.endat_error.load(std::memory_order_relaxed)),
                           static_cast<uint16_t>(c.endat_warning.load(std::memory_order_relaxed))};
    const ErrorAssessment errors =
        apply_error_policy(sample, policies_[i], words, params_[i], decode_state_[i]);
    auto bump = [](std::atomic<uint64_t>& a) {
      a.store(a.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    };
    bump(sample.fresh ? c.fresh_cycles : c.stale_cycles);
    if (sample.new_position) bump(c.new_positions);
    if (sample.stamp_too_old) bump(c.old_stamps);
    if (sample.stalled) bump(c.stalled);
    if (sample.repeated) bump(c.repeats);
    if (sample.fresh && !sample.fraction_valid) bump(c.format_violations);
    if (sample.held) bump(c.held);
    c.error_info.store(sample.error_info, std::memory_order_relaxed);
    any_fresh |= sample.fresh;
    if (io_[i].inputs_fresh && io_[i].axis_up && result.bus_up)
      c.last_input_ns.store(ctx.start_ns, std::memory_order_relaxed);

    shm::AxisStatus& st = status_[i];
    // Each fresh input is one read of all four channels, unless the bus reads them apart.
    const bool info_read = io_[i].info_acyclic ? io_[i].info_fresh : sample.fresh;
    if (info_read && st.info.configured != 0) {
      update_axis_info(st.info, io_[i].inputs.info_ok, io_[i].inputs.info, ctx.start_ns);
      for (std::size_t n = 0; n < kInfoChannels; ++n) {
        c.info_value[n].store(st.info.value[n], std::memory_order_relaxed);
        c.info_read_ns[n].store(st.info.read_ns[n], std::memory_order_relaxed);
      }
      c.info_valid.store(st.info.valid, std::memory_order_relaxed);
    }
    st.sample = sample;
    st.endat_error = words.endat_error;
    st.endat_warning = words.endat_warning;
    st.errors = errors;
    // An axis whose encoder is not (yet) the expected one is down: its positions would be another
    // encoder's under this axis' name.
    const bool identity_ok =
        identity_gate_[i] == 0 || c.identity.load(std::memory_order_relaxed) ==
                                      static_cast<uint8_t>(IdentityState::Confirmed);
    st.validity = shm::classify(sample, result.bus_up && io_[i].axis_up && identity_ok, errors);
    // A position that breaks the format is never published as valid.
    if (st.validity == shm::AxisValidity::Valid && !sample.fraction_valid)
      st.validity = shm::AxisValidity::ModuleError;
    c.position_raw.store(sample.position_raw, std::memory_order_relaxed);
    c.pos_cycle.store(sample.pos_cycle, std::memory_order_relaxed);
    if (sample.fresh) {
      c.pos_time_ns.store(sample.pos_time_ns, std::memory_order_relaxed);
      c.time_source.store(static_cast<uint8_t>(sample.time_source), std::memory_order_relaxed);
    }
    c.cycle.store(ctx.index, std::memory_order_relaxed);
    c.validity.store(static_cast<uint8_t>(st.validity), std::memory_order_relaxed);
    if (const auto v = static_cast<uint8_t>(st.validity); v != last_validity_[i]) {
      last_validity_[i] = v;
      if (incidents_ != nullptr && st.validity == shm::AxisValidity::ModuleError)
        incidents_->raise(IncidentKind::AxisError, -1, static_cast<int>(i), ctx.start_ns);
      if (incidents_ != nullptr && st.validity == shm::AxisValidity::BusDown)
        incidents_->raise(IncidentKind::AxisBusDown, -1, static_cast<int>(i), ctx.start_ns);
    }
    if (const auto v = static_cast<std::size_t>(st.validity); v < c.published.size())
      bump(c.published[v]);
  }
  const uint64_t now_us = static_cast<uint64_t>(ctx.start_ns / 1000);
  for (std::size_t i = 0; i < io_.size(); ++i) run_tunnel(i, now_us);

  if (any_fresh)
    data_exchanges_.store(data_exchanges_.load(std::memory_order_relaxed) + 1,
                          std::memory_order_relaxed);
  // The next cycle's wake-up on the engine's timeline (the start, less the spin): the
  // shared-memory wake-up thread, on the same CPU, wakes then too and runs once this thread
  // sleeps again.
  publisher_.publish(ctx, status_, ctx.start_ns + next_wake_offset_ns_);
  watch_overruns(ctx);
}

// An overrun leaves grid slots out (CycleContext::index jumps): overruns_burst of them within one
// second of cycles raise one incident for that second.
void CycleWork::watch_overruns(const CycleContext& ctx) noexcept {
  if (incidents_ == nullptr || overrun_burst_ == 0) return;
  if (!have_index_) {
    have_index_ = true;
    last_index_ = burst_window_start_ = ctx.index;
    return;
  }
  if (ctx.index - burst_window_start_ >= cycles_per_second_) {
    burst_window_start_ = ctx.index;
    burst_overruns_ = 0;
    burst_raised_ = false;
  }
  if (ctx.index > last_index_ + 1) ++burst_overruns_;
  last_index_ = ctx.index;
  if (!burst_raised_ && burst_overruns_ >= overrun_burst_) {
    burst_raised_ = true;
    incidents_->raise(IncidentKind::OverrunBurst, -1, -1, ctx.start_ns);
  }
}

}  // namespace ds1928

namespace ds1928 {

void CycleWork::run_tunnel(std::size_t axis, uint64_t now_us) noexcept {
  Tunnel& t = *tunnels_[axis];
  auto event = [&t](const TunnelEvent& e) {
    if (!t.events.try_push(e)) {
      t.counters.events_dropped.store(t.counters.events_dropped.load(std::memory_order_relaxed) + 1,
                                      std::memory_order_relaxed);
    }
  };
  for (std::size_t n = 0; n < 4; ++n) {  // a few per cycle: bounded work
    auto request = t.requests.try_pop();
    if (!request) break;
    if (request->kind == TunnelRequest::Kind::ResetChannel) {
      t.channel.reset();
      continue;
    }
    const auto ec = t.channel.submit(std::span<const uint8_t>(request->bytes.data(), request->size),
                                     request->tag);
    if (ec) {
      TunnelEvent e;
      e.kind = TunnelEvent::Kind::Rejected;
      e.tag = request->tag;
      e.result = static_cast<flatstream::Errc>(ec.value());
      event(e);
    }
  }
  // The module's InputSequence/RxBytes of this cycle → OutputSequence/TxBytes of the next.
  AxisIo& io = io_[axis];
  const auto out = t.channel.step(flatstream::input_frame(io.inputs), now_us);
  flatstream::apply(out, io.outputs);

  while (auto outcome = t.channel.take_outcome()) {
    TunnelEvent e;
    e.kind = outcome->delivered() ? TunnelEvent::Kind::Sent : TunnelEvent::Kind::SendFailed;
    e.tag = outcome->tag;
    e.result = outcome->result;
    event(e);
  }
  while (t.channel.take_received(t.received)) {
    TunnelEvent e;
    e.kind = TunnelEvent::Kind::Received;
    e.full_size = t.received.size;
    e.size = static_cast<uint8_t>(std::min<std::size_t>(t.received.size, kTunnelMessageMax));
    std::copy_n(t.received.bytes.begin(), e.size, e.bytes.begin());
    event(e);
  }
  const auto c = t.channel.counters();
  const auto st = t.channel.state();
  TunnelCounters& tc = t.counters;
  tc.messages_sent.store(c.sent.messages_delivered, std::memory_order_relaxed);
  tc.messages_failed.store(c.sent.messages_failed, std::memory_order_relaxed);
  tc.messages_received.store(c.received.messages_received, std::memory_order_relaxed);
  tc.sequences_repeated.store(c.sent.sequences_repeated, std::memory_order_relaxed);
  tc.resyncs.store(c.sent.resyncs + c.received.resyncs, std::memory_order_relaxed);
  tc.output_state.store(static_cast<uint8_t>(st.sending), std::memory_order_relaxed);
  tc.input_state.store(static_cast<uint8_t>(st.receiving), std::memory_order_relaxed);
}

}  // namespace ds1928
