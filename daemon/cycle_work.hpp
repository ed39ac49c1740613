// The work of one cycle (docs/design.md §2 "One cycle"): exchange with the bus, decode each
// axis, run its Flatstream channel, publish to shared memory. Runs on the cycle thread; the
// normal thread talks to it only through the lock-free queues and atomics below.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "config/config.hpp"
#include "config/config_loader.hpp"
#include "core/axis_sample.hpp"
#include "core/bus.hpp"
#include "core/cycle_engine.hpp"
#include "core/incident.hpp"
#include "core/spsc_queue.hpp"
#include "flatstream/channel.hpp"
#include "shm/publisher.hpp"

namespace ds1928 {

// A request from the normal thread for the cycle thread.
struct AxisCommand {
  enum class Kind : uint8_t { AckErrors };
  Kind kind = Kind::AckErrors;
  uint16_t axis = 0;
  uint8_t bits = 0;
};

// Longest Flatstream message that crosses between the threads. EnDat commands and replies are at
// most 10 bytes; anything longer from the module is reported as oversized, never cut silently.
inline constexpr std::size_t kTunnelMessageMax = 32;

// Normal thread → cycle thread: one Flatstream message for an axis, or a channel reset.
struct TunnelRequest {
  enum class Kind : uint8_t { Message, ResetChannel };
  Kind kind = Kind::Message;
  uint32_t tag = 0;
  uint8_t size = 0;
  std::array<uint8_t, kTunnelMessageMax> bytes{};
};

// Cycle thread → normal thread: what happened to a message, or a message from the module.
struct TunnelEvent {
  enum class Kind : uint8_t {
    Sent,        // every sequence of message `tag` acknowledged by the module
    SendFailed,  // message `tag` not delivered: `result` says why
    Rejected,    // message `tag` not accepted by the channel (queue full / too long)
    Received,    // a complete message from the module
  };
  Kind kind = Kind::Received;
  uint32_t tag = 0;
  flatstream::Errc result = flatstream::Errc::ok;
  uint16_t full_size = 0;  // the received message's real size (> kTunnelMessageMax: oversized)
  uint8_t size = 0;        // bytes kept
  std::array<uint8_t, kTunnelMessageMax> bytes{};
};

// Flatstream figures of one axis (single writer: the cycle thread).
struct TunnelCounters {
  std::atomic<uint64_t> messages_sent{0};
  std::atomic<uint64_t> messages_failed{0};
  std::atomic<uint64_t> messages_received{0};
  std::atomic<uint64_t> sequences_repeated{0};
  std::atomic<uint64_t> resyncs{0};
  std::atomic<uint64_t> events_dropped{0};  // event queue full: the normal thread fell behind
  std::atomic<uint8_t> output_state{0};     // flatstream::SenderState
  std::atomic<uint8_t> input_state{0};      // flatstream::ReceiverState
};

// Whether the encoder behind an axis is the one the configuration expects
// (axes[].expected_encoder; the EnDat service compares at identification).
enum class IdentityState : uint8_t {
  Unchecked = 0,   // nothing expected
  Pending = 1,     // expected, not identified yet
  Confirmed = 2,   // identified and as expected
  Mismatch = 3,    // identified and not as expected
  Unreadable = 4,  // the identification failed
};

// Per-axis figures the normal thread reads for `status` (single writer: the cycle thread).
struct AxisCounters {
  std::atomic<uint64_t> fresh_cycles{0};
  std::atomic<uint64_t> stale_cycles{0};
  std::atomic<uint64_t> new_positions{0};
  std::atomic<uint64_t> format_violations{0};  // fraction with low 3 bits set
  std::atomic<uint64_t> old_stamps{0};  // new positions stamped too long ago (a late PRes), stale
  std::atomic<uint64_t> repeats{0};     // samples repeating the last position (not new)
  std::atomic<uint64_t> stalled{0};     // repeats beyond the stall limit: published stale
  std::atomic<uint64_t> held{0};  // cycles an analogue error held the last good position (stale)
  std::atomic<uint8_t> error_info{0};
  // Last sample, for human-readable status only (fields are not read as one consistent set;
  // applications read the seqlock record in shared memory).
  std::atomic<uint64_t> position_raw{0};
  std::atomic<int8_t> pos_cycle{0};
  std::atomic<int64_t> pos_time_ns{0};
  std::atomic<uint8_t> time_source{0};     // TimeSource
  std::atomic<uint64_t> cycle{0};          // cycle index of the last publication
  std::atomic<uint8_t> validity{0};        // shm::AxisValidity
  std::atomic<uint32_t> endat_error{0};    // written by the normal thread from acyclic reads
  std::atomic<uint32_t> endat_warning{0};  // idem
  std::atomic<uint8_t> identity{0};        // IdentityState, written by the normal thread
  // Cycles published per shm::AxisValidity (the metrics endpoint's publications by validity).
  std::array<std::atomic<uint64_t>, 4> published{};
  // The additional-information channels as last published (status and metrics; each field
  // alone is consistent, applications read the seqlock record).
  std::array<std::atomic<int32_t>, kInfoChannels> info_value{};
  std::array<std::atomic<int64_t>, kInfoChannels> info_read_ns{};  // 0: never valid
  std::atomic<uint8_t> info_valid{0};
  // Cycle start (CLOCK_MONOTONIC) of the last cycle whose exchange brought the module's inputs
  // (new or repeated) with the axis' part of the bus up; 0: never. The module state
  // (module_leds.hpp) reads it.
  std::atomic<int64_t> last_input_ns{0};
};

class CycleWork final : public CycleTask {
 public:
  static constexpr uint32_t kAckHoldCycles = 8;  // AckErrorInfo stays set this many cycles

  CycleWork(const DaemonConfig& config, BusDriver& bus, shm::Publisher& publisher);

  void run_cycle(const CycleContext& ctx) noexcept override;

  // Normal thread. False when the queue is full (the caller reports "busy").
  [[nodiscard]] bool post(const AxisCommand& command) noexcept {
    return commands_.try_push(command);
  }

  // Normal thread: the axis' Flatstream tunnel. False when its queue is full.
  [[nodiscard]] bool submit_tunnel(std::size_t axis, const TunnelRequest& request) noexcept {
    return axis < tunnels_.size() && tunnels_[axis]->requests.try_push(request);
  }
  [[nodiscard]] std::optional<TunnelEvent> poll_tunnel(std::size_t axis) noexcept {
    if (axis >= tunnels_.size()) return std::nullopt;
    return tunnels_[axis]->events.try_pop();
  }
  [[nodiscard]] const TunnelCounters& tunnel_counters(std::size_t axis) const noexcept {
    return tunnels_[axis]->counters;
  }

  [[nodiscard]] std::size_t axis_count() const noexcept { return io_.size(); }
  [[nodiscard]] AxisCounters& counters(std::size_t axis) noexcept { return counters_[axis]; }
  [[nodiscard]] uint64_t exchanges() const noexcept {
    return exchanges_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] uint64_t data_exchanges() const noexcept {
    return data_exchanges_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] uint64_t frames_lost() const noexcept {
    return frames_lost_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] bool bus_up() const noexcept { return bus_up_.load(std::memory_order_relaxed); }
  // Start (CLOCK_MONOTONIC) of the last cycle run; 0 before the first.
  [[nodiscard]] int64_t last_cycle_ns() const noexcept {
    return last_cycle_ns_.load(std::memory_order_relaxed);
  }

  // Normal thread, before the cycle thread starts: where the cycle work raises its incidents (an
  // axis going to module_error or bus_down, a burst of overruns). nullptr: none.
  void set_incident_sink(IncidentSink* sink) noexcept { incidents_ = sink; }

 private:
  struct Tunnel {
    explicit Tunnel(const flatstream::MasterConfig& c) : channel(c) {}
    flatstream::MasterChannel channel;
    SpscQueue<TunnelRequest, 16> requests;
    SpscQueue<TunnelEvent, 64> events;
    TunnelCounters counters;
    flatstream::Message received;  // scratch, so the 512-byte message is not on the stack
  };
  void run_tunnel(std::size_t axis, uint64_t now_us) noexcept;
  void watch_overruns(const CycleContext& ctx) noexcept;

  BusDriver& bus_;
  shm::Publisher& publisher_;
  // Sized once at construction; never resized on the cycle thread.
  std::vector<AxisIo> io_;
  std::vector<AxisDecodeParams> params_;
  std::vector<ErrorPolicy> policies_;  // the error bits' effects (axes[].invalidate_on)
  std::vector<AxisDecodeState> decode_state_;
  std::vector<shm::AxisStatus> status_;
  std::vector<uint8_t> ack_bits_;
  std::vector<uint32_t> ack_hold_;
  std::unique_ptr<AxisCounters[]> counters_;
  int64_t next_wake_offset_ns_;  // cycle start -> the engine's next wake-up (period - spin)
  std::vector<std::unique_ptr<Tunnel>> tunnels_;
  SpscQueue<AxisCommand, 64> commands_;
  std::atomic<uint64_t> exchanges_{0};
  std::atomic<uint64_t> data_exchanges_{0};
  std::atomic<uint64_t> frames_lost_{0};
  std::atomic<bool> bus_up_{false};
  std::atomic<int64_t> last_cycle_ns_{0};
  // Incidents (flight recorder): the last validity per axis, overruns in the current second.
  IncidentSink* incidents_ = nullptr;
  // Per axis: the axis is up only once its encoder is confirmed (expected_encoder set and
  // topology.on_mismatch refuse).
  std::vector<uint8_t> identity_gate_;
  std::vector<uint8_t> last_validity_;
  uint32_t overrun_burst_ = 0;
  uint64_t cycles_per_second_ = 1;
  bool have_index_ = false;
  uint64_t last_index_ = 0;
  uint64_t burst_window_start_ = 0;
  uint32_t burst_overruns_ = 0;
  bool burst_raised_ = false;
};

}  // namespace ds1928
