// BusDriver for `bus: canio`: X20DS1928 modules in function model 254 behind CAN-I/O bus
// controllers, over a CanPort (SocketCAN or the virtual test bus).
//
// One cycle (exchange(), cycle thread): drain what arrived since the last deadline (late: counted,
// never used), SYNC, every axis' output object, then input objects until every axis has its pair
// or the response window (canio_timing(): bit budget + node reaction) ends. Which objects make a
// sample is decided by SyncPairing (sync_pairing.hpp): only objects stamped between this SYNC and
// the deadline, object 2 only after object 1, exactly one each — a sample never combines two
// SYNCs. Its time stamp is the RX stamp of object 1 (function model 254 has no PosTime).
//
// Per axis (CanioAxisState): Configuring (its node is being configured: only this axis is
// BusDown), AwaitingPosCycle (configured, but PosCycle has not changed since: Stale), Operational,
// Silent (no complete sample for input_timeout_ms: Stale). Other axes are not affected.
//
// Acyclic registers (configuration, Rescan, identification, EnDatError/EnDatWarning) go through
// expedited CANopen SDO on a second port owned by a normal-priority worker (canio_sdo_worker.cpp),
// paced to one transfer a cycle so that the bus-load budget holds.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "canio/can_port.hpp"
#include "canio/canio_options.hpp"
#include "canio/object_codec.hpp"
#include "canio/sdo_expedited.hpp"
#include "canio/sync_pairing.hpp"
#include "core/bus.hpp"
#include "core/spsc_queue.hpp"
#include "powerlink/sdo_mapping.hpp"

namespace ds1928::canio {

enum class CanioBusError : int {
  kNoAcyclicTransport = 1,  // acyclic.transport none: the module cannot be configured
  kSdoTimeout,              // no SDO response within sdo_timeout_ms
  kReadBackMismatch,        // a written register reads back another value
  kNoSdoObject,             // the register has no SDO object (index/subindex)
  kNotConfigured,           // the axis' module is not configured (yet)
  kSdoSendFailed,           // the SDO request could not be sent (bus-off, queue full, down)
  kNoSuchAxis,
  kReadBackSize,  // a register reads back with another size than it has
};
[[nodiscard]] const std::error_category& canio_bus_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(CanioBusError e) noexcept {
  return {static_cast<int>(e), canio_bus_category()};
}

inline constexpr std::size_t kMaxCanioAxes = 64;

// Where an axis stands (cycle thread writes, any thread reads).
enum class CanioAxisState : uint8_t {
  Configuring = 0,       // the worker configures its module: the axis is BusDown (only it)
  AwaitingPosCycle = 1,  // configured; Stale until PosCycle changes (a real new position)
  Operational = 2,       // fresh samples are published
  Silent = 3,            // configured, but no complete sample for input_timeout_ms: Stale
};
[[nodiscard]] std::string_view to_string(CanioAxisState s) noexcept;
// Why an axis in this state is not Valid, for status (empty when Operational).
[[nodiscard]] std::string_view reason(CanioAxisState s) noexcept;

// Per-axis figures (single writer: the cycle thread, or the SDO worker where noted).
struct CanioAxisCounters {
  std::atomic<uint64_t> samples{0};         // both objects of a cycle: fresh
  std::atomic<uint64_t> half_samples{0};    // only one of the two input objects arrived
  std::atomic<uint64_t> missing{0};         // neither arrived
  std::atomic<uint64_t> duplicates{0};      // more objects than one SYNC explains: dropped
  std::atomic<uint64_t> unpaired{0};        // both objects there, SYNC not certain: dropped
  std::atomic<uint64_t> wrong_length{0};    // an object with dlc ≠ 8: ignored
  std::atomic<uint64_t> late_frames{0};     // answer to an earlier SYNC: ignored
  std::atomic<uint64_t> gated{0};           // whole samples held back until PosCycle changed
  std::atomic<uint64_t> sdo_transfers{0};   // SDO worker
  std::atomic<uint64_t> sdo_errors{0};      // SDO worker
  std::atomic<uint64_t> configurations{0};  // SDO worker: completed start-up configurations
  std::atomic<uint64_t> unverified{0};      // SDO worker: writes whose read-back was refused
  std::atomic<uint64_t> rescans{0};         // SDO worker: EnDatAck bit 1 written
  std::atomic<uint32_t> generation{0};      // SDO worker: bumped by every (re)configuration
  std::atomic<bool> configured{false};      // SDO worker writes, cycle thread reads
  std::atomic<CanioAxisState> state{CanioAxisState::Configuring};  // cycle thread
  std::atomic<bool> silent{true};  // no complete sample for input_timeout_ms
  std::atomic<int64_t> last_sample_ns{0};
};

// Bus-wide figures.
struct CanioBusCounters {
  std::atomic<uint64_t> cycles{0};
  std::atomic<uint64_t> sync_sent{0};
  std::atomic<uint64_t> tx_queue_full{0};   // ENOBUFS / EAGAIN: frame dropped, not retried
  std::atomic<uint64_t> tx_failed{0};       // bus-off, interface down, other errors
  std::atomic<uint64_t> unexpected_ids{0};  // data frames with an identifier no axis uses
  std::atomic<uint64_t> error_frames{0};
  std::atomic<uint64_t> receive_errors{0};  // port receive failures (interface down)
  std::atomic<uint64_t> bus_off_cycles{0};  // cycles skipped while bus-off / down
  std::atomic<int64_t> last_window_ns{0};   // last SYNC → last object of the cycle
};

struct CanioAxisPlan {
  uint8_t node = 1;
  uint8_t slot = 1;
  CanioAxisIds ids;
  ModuleSettings module;
  std::string name;
};

struct CanioBusOptions {
  CanioBusConfig bus;
  std::vector<CanioAxisPlan> axes;
  uint32_t period_us = 2000;
  uint32_t response_window_us = 0;  // canio_timing(): configured or derived
  // Tests that drive exchange() without a module to configure (the position-integrity test):
  // every axis counts as configured from the start.
  bool assume_configured = false;
};

// Start-up check of a port's interface (state, bit rate) against the configuration, the same
// words for SocketCAN and the virtual bus: empty when usable, else the message naming the fix.
[[nodiscard]] std::string check_interface(CanPort& port, uint32_t expected_bitrate);

// The driver's plan of every configured axis (identifiers resolved, response window derived)
// from the bus' options, the axes (in exchange() order) and the cycle period.
[[nodiscard]] CanioBusOptions make_canio_options(const CanioBusConfig& bus,
                                                 std::span<const AxisConfig> axes,
                                                 uint32_t period_us);

class CanioBus final : public BusDriver {
 public:
  // `cycle_port` carries the cyclic objects (cycle thread), `sdo_port` the SDO transfers (worker
  // thread); both may be the same kind of port on the same interface.
  CanioBus(CanioBusOptions options, std::unique_ptr<CanPort> cycle_port,
           std::unique_ptr<CanPort> sdo_port);
  ~CanioBus() override;
  CanioBus(const CanioBus&) = delete;
  CanioBus& operator=(const CanioBus&) = delete;

  [[nodiscard]] std::string_view name() const noexcept override { return "canio"; }
  // Filters and error frames on both ports, the interface's state; refuses an axis whose module
  // cannot be configured (acyclic transport none) with start_error() saying why; starts the SDO
  // worker, which configures the modules.
  [[nodiscard]] std::error_code start() override;
  void stop() noexcept override;
  ExchangeResult exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                          uint64_t cycle_index) noexcept override;
  [[nodiscard]] BusState state() const noexcept override {
    return state_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] bool submit(const RegisterRequest& request) noexcept override;
  [[nodiscard]] bool poll(RegisterResult& out) noexcept override;

  // Normal thread: why start() failed, in words.
  [[nodiscard]] const std::string& start_error() const noexcept { return start_error_; }
  // Any thread.
  [[nodiscard]] const CanioBusOptions& options() const noexcept { return options_; }
  [[nodiscard]] const CanioAxisCounters& axis_counters(std::size_t axis) const noexcept {
    return axis_counters_[axis];
  }
  [[nodiscard]] const CanioBusCounters& counters() const noexcept { return counters_; }
  [[nodiscard]] CanState can_state() const noexcept { return cycle_port_->state(); }
  [[nodiscard]] CanPortCounters port_counters() const noexcept { return cycle_port_->counters(); }
  [[nodiscard]] std::string_view port_name() const noexcept { return cycle_port_->name(); }
  // Normal thread: the interface as netlink (or the virtual bus) last reported it.
  [[nodiscard]] CanInterfaceInfo interface_info() const;
  // Last SDO worker error per axis (configuration or transfer), for status. Normal thread.
  [[nodiscard]] std::string axis_last_error(std::size_t axis) const;

  // Clock (CLOCK_MONOTONIC ns) of the response deadline and the node timeouts; tests replace it
  // together with the virtual bus' clock.
  using Clock = int64_t (*)() noexcept;
  void set_clock(Clock clock) noexcept { clock_ = clock; }

 private:
  struct ObjectRoute {
    uint32_t id = 0;
    uint16_t axis = 0;
    ObjectKind kind = ObjectKind::Position;
  };
  // One axis on the cycle thread: the pairing and the PosCycle gate.
  struct Track {
    SyncPairing pairing;
    uint32_t generation = 0;  // the configuration the gate refers to
    bool gated = false;       // since (re)configuration PosCycle has not changed
    bool gate_have = false;   // gate_pos_cycle holds the first sample's PosCycle
    int8_t gate_pos_cycle = 0;
  };
  enum class Stamp { Before, Window, After };
  void handle_frame(const CanFrame& f, Stamp where) noexcept;
  [[nodiscard]] bool window_complete(std::size_t n) const noexcept;
  [[nodiscard]] const ObjectRoute* route(uint32_t id) const noexcept;
  void count_send(SendResult r) noexcept;

  // SDO worker.
  void worker() noexcept;
  [[nodiscard]] std::error_code configure_axis(std::size_t axis);
  // The module's read-back after a silence: Unknown when an SDO transfer failed (timeout,
  // abort), which says nothing about the module's configuration.
  enum class ConfigurationCheck { Intact, Changed, Unknown };
  [[nodiscard]] ConfigurationCheck check_configuration(std::size_t axis);
  // `answered_size` gets the size of the answer (0: none); `expected` 0 accepts any size.
  [[nodiscard]] std::error_code sdo_read(std::size_t axis, uint16_t reg, uint8_t size,
                                         uint32_t& value, uint8_t* answered_size = nullptr);
  [[nodiscard]] std::error_code sdo_write(std::size_t axis, uint16_t reg, uint8_t size,
                                          uint32_t value, bool verify);
  [[nodiscard]] std::error_code sdo_transfer(uint8_t node, const SdoMessage& request,
                                             uint8_t expected_size, uint32_t& value,
                                             uint8_t* answered_size);
  void pace_sdo() noexcept;
  void set_last_error(std::size_t axis, const std::string& text);

  CanioBusOptions options_;
  std::unique_ptr<CanPort> cycle_port_;
  std::unique_ptr<CanPort> sdo_port_;
  powerlink::SdoMapping sdo_mapping_;
  ByteOrder order_ = ByteOrder::Little;
  std::vector<ObjectRoute> routes_;  // sorted by id; fixed after construction
  std::vector<Track> track_;
  std::unique_ptr<CanioAxisCounters[]> axis_counters_;
  CanioBusCounters counters_;
  std::array<CanFrame, 64> rx_{};
  int64_t sync_tx_ns_ = 0;  // this cycle's window
  int64_t deadline_ns_ = 0;
  std::atomic<BusState> state_{BusState::Down};
  std::atomic<bool> reconfigure_[kMaxCanioAxes]{};
  Clock clock_;
  std::string start_error_;

  SpscQueue<RegisterRequest, 64> requests_;
  SpscQueue<RegisterResult, 64> results_;
  std::thread worker_;
  std::chrono::steady_clock::time_point last_sdo_{};  // worker: pacing
  std::atomic<bool> stop_{false};
  std::mutex wake_mutex_;  // worker wake-up only (normal threads)
  std::condition_variable wake_;
  mutable std::mutex info_mutex_;  // normal threads only
  CanInterfaceInfo info_;
  std::vector<std::string> last_error_;
};

}  // namespace ds1928::canio

namespace std {
template <>
struct is_error_code_enum<ds1928::canio::CanioBusError> : true_type {};
}  // namespace std
