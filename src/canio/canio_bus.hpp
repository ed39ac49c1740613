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
// Node lifecycle (CiA 301, canio_nmt.cpp): after configuring every module of a node the driver
// sends NMT Start to it (canio.nmt: start), and repeats it with a bounded back-off while the node
// stays silent; the node port watches boot-up / heartbeat (0x700 + node) and EMCY (0x080 +
// node). A boot-up means the node lost its settings: its axes go down at once and are configured
// again; a missed heartbeat takes them down until a check proves the configuration. After a
// bus-off every axis is checked again before it is trusted. Each such event is counted per node
// and queued as a CanioNodeEvent (poll_event()): the one place the daemon hears of them.
//
// Acyclic registers (configuration, Rescan, identification, EnDatError/EnDatWarning) go through
// expedited CANopen SDO on a second port, as a state machine stepped by the same cycle that owns
// the bus (canio_sdo.cpp), like POWERLINK's SDO in the ManagingNode: after each response window
// exchange() takes the SDO answers, checks the transfer's timeout on the cycle's clock and starts
// the next transfer, at most one a cycle and one per max(period, sdo_interval_us) so that the
// bus-load budget holds. No thread, no sleep, no allocation or lock on the cycle thread.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "can/can_port.hpp"
#include "canio/canio_options.hpp"
#include "canio/canopen_nmt.hpp"
#include "canio/object_codec.hpp"
#include "canio/sdo_client.hpp"
#include "canio/sdo_expedited.hpp"
#include "canio/sync_pairing.hpp"
#include "core/bus.hpp"
#include "core/spsc_queue.hpp"
#include "x20ds1928/info_channels.hpp"
#include "x20ds1928/object_dictionary.hpp"
#include "x20ds1928/sdo_mapping.hpp"

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
  kNodeReset,     // the node announced a reset (boot-up) during the transfer's job
};
[[nodiscard]] const std::error_category& canio_bus_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(CanioBusError e) noexcept {
  return {static_cast<int>(e), canio_bus_category()};
}

inline constexpr std::size_t kMaxCanioAxes = 64;
// Register requests the driver holds: submitted, waiting for their axis, results not polled.
inline constexpr std::size_t kSdoQueueDepth = kRegisterQueueDepth;

// Where an axis stands (cycle thread writes, any thread reads).
enum class CanioAxisState : uint8_t {
  Configuring = 0,       // its module is being configured over SDO: the axis is BusDown (only it)
  AwaitingPosCycle = 1,  // configured; Stale until PosCycle changes (a real new position)
  Operational = 2,       // fresh samples are published
  Silent = 3,            // configured, but no complete sample for input_timeout_ms: Stale
  Starting = 4,          // configured, NMT Start sent, no process data yet (Start repeated)
  Unconfigurable = 5,    // a register the axis needs was refused (abort): retried with back-off
  IdentityMismatch = 6,  // its node's identity (0x1000 / 0x1018) is not the expected one:
                         // not configured, not started; checked again with back-off
};
[[nodiscard]] std::string_view to_string(CanioAxisState s) noexcept;
// Why an axis in this state is not Valid, for status (empty when Operational).
[[nodiscard]] std::string_view reason(CanioAxisState s) noexcept;

// Per-axis figures (single writer: the cycle thread; "SDO": its register access).
struct CanioAxisCounters {
  std::atomic<uint64_t> samples{0};         // both objects of a cycle: fresh
  std::atomic<uint64_t> half_samples{0};    // only one of the two input objects arrived
  std::atomic<uint64_t> missing{0};         // neither arrived
  std::atomic<uint64_t> duplicates{0};      // more objects than one SYNC explains: dropped
  std::atomic<uint64_t> unpaired{0};        // both objects there, SYNC not certain: dropped
  std::atomic<uint64_t> wrong_length{0};    // an object with dlc ≠ 8: ignored
  std::atomic<uint64_t> late_frames{0};     // answer to an earlier SYNC: ignored
  std::atomic<uint64_t> gated{0};           // whole samples held back until PosCycle changed
  std::atomic<uint64_t> sdo_transfers{0};   // SDO: transfers started
  std::atomic<uint64_t> sdo_errors{0};      // SDO: failed transfers, configurations, checks
  std::atomic<uint64_t> configurations{0};  // SDO: completed start-up configurations
  std::atomic<uint64_t> unverified{0};      // SDO: writes whose read-back was refused
  std::atomic<uint64_t> rescans{0};         // SDO: EnDatAck bit 1 written
  std::atomic<uint32_t> generation{0};      // SDO: bumped by every (re)configuration
  std::atomic<bool> configured{false};      // SDO: the module is configured (status reads it)
  std::atomic<CanioAxisState> state{CanioAxisState::Configuring};  // cycle thread
  std::atomic<bool> silent{true};           // no complete sample for input_timeout_ms
  std::atomic<bool> unconfigurable{false};  // SDO: a register it needs was refused
  std::atomic<uint64_t> write_aborts{0};    // SDO: configuration writes refused (abort)
  std::atomic<int64_t> last_sample_ns{0};
};

// Per CANopen node (cycle thread writes, any thread reads).
struct CanioNodeCounters {
  uint8_t node = 0;                            // fixed after construction
  std::atomic<uint64_t> nmt_starts{0};         // NMT Start sent (after each configuration)
  std::atomic<uint64_t> start_retries{0};      // Start repeated: configured but silent after it
  std::atomic<uint64_t> boot_ups{0};           // boot-up messages (the node reset)
  std::atomic<uint64_t> heartbeats{0};         // heartbeat messages received
  std::atomic<uint64_t> heartbeat_misses{0};   // consumer timeouts
  std::atomic<uint64_t> emcys{0};              // EMCY messages received
  std::atomic<uint64_t> last_emcy{0};          // code | register << 16 | vendor << 24
  std::atomic<uint8_t> nmt_state{0xFF};        // last reported (canio::NmtState), 0xFF: none
  std::atomic<bool> heartbeat_watched{false};  // consumer armed (0x1017 written)
  // The last identity check (canio_identity.cpp), published under a sequence counter (odd while
  // it changes) by the cycle thread.
  std::atomic<uint32_t> identity_seq{0};
  std::atomic<uint8_t> identity_state{0};  // NodeIdentityState
  std::atomic<uint8_t> identity_read{0}, identity_unreadable{0};
  std::array<std::atomic<uint32_t>, 5> identity_found{};
  std::atomic<int> identity_error{0};
  std::atomic<const std::error_category*> identity_category{nullptr};
  std::atomic<uint64_t> identity_checks{0};
  std::atomic<uint64_t> identity_mismatches{0};
};

// The identity objects a node is checked by (CiA 301), in the order they are read: one table,
// indexed by the positions of CanioNodeIdentity's arrays.
struct IdentityField {
  std::string_view key;  // the configuration key (canio.nodes[], powerlink.nodes[])
  uint16_t index = 0;
  uint8_t subindex = 0;
};
inline constexpr std::array<IdentityField, 5> kIdentityFields{{{"device_type", 0x1000, 0},
                                                               {"vendor_id", 0x1018, 1},
                                                               {"product_code", 0x1018, 2},
                                                               {"revision_no", 0x1018, 3},
                                                               {"serial_no", 0x1018, 4}}};
enum class NodeIdentityState : uint8_t {
  Unchecked = 0,   // no identity expected (canio.nodes[] without identity keys): not read
  Pending = 1,     // expected, not read yet (since start or the node's last boot-up)
  Confirmed = 2,   // every expected object read and equal
  Mismatch = 3,    // an object differs
  Unreadable = 4,  // an expected object could not be read (an SDO abort: no such object)
};
[[nodiscard]] std::string_view to_string(NodeIdentityState s) noexcept;
// What the last identity check of a node found (normal thread: CanioBus::node_identity()).
struct NodeIdentity {
  NodeIdentityState state = NodeIdentityState::Unchecked;
  uint8_t expected_mask = 0;    // bit f: kIdentityFields[f] is expected
  uint8_t read_mask = 0;        // bit f: found[f] was read
  uint8_t unreadable_mask = 0;  // bit f: the read was refused (error)
  std::array<uint32_t, 5> expected{};
  std::array<uint32_t, 5> found{};
  std::error_code error;  // the first refused read's
  uint64_t checks = 0;    // identity checks completed
  uint64_t mismatches = 0;
};
// "identity: product_code 0x00002928, expected 0x00001928 (0x1018/2)", differences joined by
// "; "; empty when as expected or not checked. Pure.
[[nodiscard]] std::string describe_identity(const NodeIdentity& id);

// A node event the daemon logs (and may hook, e.g. a flight recorder): queued by the cycle thread,
// taken by the normal thread with CanioBus::poll_event().
enum class CanioNodeEventKind : uint8_t {
  BootUp,             // the node announced a reset: its axes are configured again
  HeartbeatMissed,    // no heartbeat within the consumer timeout: its axes are down
  Emcy,               // an emergency message (code, register, vendor bytes)
  StartRetry,         // configured but silent after NMT Start: Start sent again
  BusOff,             // the controller went bus-off (node 0: the whole bus)
  BusRestarted,       // the controller is back: every axis is checked before it is trusted
  IdentityMismatch,   // the node's identity differs (or cannot be read): node_identity()
  IdentityConfirmed,  // ... and is as expected again
};
[[nodiscard]] std::string_view to_string(CanioNodeEventKind k) noexcept;
struct CanioNodeEvent {
  CanioNodeEventKind kind = CanioNodeEventKind::BootUp;
  uint8_t node = 0;     // 0: the bus
  int64_t time_ns = 0;  // driver clock
  Emcy emcy{};          // Emcy
  uint32_t detail = 0;  // StartRetry: next back-off ms; HeartbeatMissed: timeout ms
};
inline constexpr std::size_t kNodeEventQueueDepth = 64;

// Bus-wide figures.
struct CanioBusCounters {
  std::atomic<uint64_t> cycles{0};
  std::atomic<uint64_t> sync_sent{0};
  std::atomic<uint64_t> tx_queue_full{0};   // ENOBUFS / EAGAIN: frame dropped, not retried
  std::atomic<uint64_t> tx_failed{0};       // bus-off, interface down, other errors
  std::atomic<uint64_t> unexpected_ids{0};  // data frames with an identifier no axis uses
  std::atomic<uint64_t> error_frames{0};
  std::atomic<uint64_t> receive_errors{0};       // port receive failures (interface down)
  std::atomic<uint64_t> bus_off_cycles{0};       // cycles skipped while bus-off / down
  std::atomic<int64_t> last_window_ns{0};        // last SYNC → last object of the cycle
  std::atomic<uint64_t> bus_errors_filtered{0};  // bus-error frames dropped before the cycle
  std::atomic<uint64_t> bus_restarts{0};         // back from bus-off / down: axes checked again
  std::atomic<uint64_t> events_dropped{0};       // node events the normal thread did not take
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
  // topology.on_mismatch: true (refuse): a node whose identity differs is not configured or
  // started, its axes stay down; false (warn): reported, the node is configured all the same.
  bool identity_refuse = true;
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

class CanioBus final : public BusDriver, private RegisterTarget {
 public:
  // `cycle_port` carries the cyclic objects, `sdo_port` the SDO transfers (both used by the cycle
  // thread only: two sockets so that SDO answers never wake the response window's receive); both
  // may be the same kind of port on the same interface.
  CanioBus(CanioBusOptions options, std::unique_ptr<CanPort> cycle_port,
           std::unique_ptr<CanPort> sdo_port);
  ~CanioBus() override;
  CanioBus(const CanioBus&) = delete;
  CanioBus& operator=(const CanioBus&) = delete;

  [[nodiscard]] std::string_view name() const noexcept override { return "canio"; }
  // Filters and error frames on both ports, the interface's state; refuses an axis whose module
  // cannot be configured (acyclic transport none) with start_error() saying why; every module is
  // then configured over SDO by the cycles that follow.
  [[nodiscard]] std::error_code start() override;
  void stop() noexcept override;
  ExchangeResult exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                          uint64_t cycle_index) noexcept override;
  [[nodiscard]] BusState state() const noexcept override {
    return state_.load(std::memory_order_relaxed);
  }

  // Normal thread: why start() failed, in words.
  [[nodiscard]] const std::string& start_error() const noexcept { return start_error_; }
  // Any thread.
  [[nodiscard]] const CanioBusOptions& options() const noexcept { return options_; }
  [[nodiscard]] const CanioAxisCounters& axis_counters(std::size_t axis) const noexcept {
    return axis_counters_[axis];
  }
  [[nodiscard]] const CanioBusCounters& counters() const noexcept { return counters_; }
  [[nodiscard]] std::size_t node_count() const noexcept { return nodes_.size(); }
  [[nodiscard]] const CanioNodeCounters& node_counters(std::size_t k) const noexcept {
    return node_counters_[k];
  }
  // Normal thread: node k's expected identity and what its last check found.
  [[nodiscard]] NodeIdentity node_identity(std::size_t k) const noexcept;
  // Normal thread: the next node event (boot-up, missed heartbeat, EMCY, Start repeated,
  // bus-off): false when none is queued.
  [[nodiscard]] bool poll_event(CanioNodeEvent& out) noexcept;
  // Why an axis is not Valid (status `reason`): the state's reason, with the refused register
  // and abort text when it is unconfigurable.
  [[nodiscard]] std::string axis_reason(std::size_t axis) const;
  [[nodiscard]] CanState can_state() const noexcept { return cycle_port_->state(); }
  [[nodiscard]] CanPortCounters port_counters() const noexcept { return cycle_port_->counters(); }
  [[nodiscard]] std::string_view port_name() const noexcept { return cycle_port_->name(); }
  // Frames the driver sends a cycle (SYNC, output objects, at most one SDO request): how many
  // cycles of old frames a full TX queue replays after a silence.
  [[nodiscard]] uint32_t tx_frames_per_cycle() const noexcept {
    return static_cast<uint32_t>(options_.axes.size()) + (options_.bus.sync_enabled ? 1u : 0u) + 1u;
  }
  // Normal thread: the interface as netlink (or the virtual bus) last reported it.
  [[nodiscard]] CanInterfaceInfo interface_info() const;
  // Last SDO error per axis (configuration, check after silence), for status. Any thread: the
  // cycle thread records what failed in fixed fields, the text is composed here.
  [[nodiscard]] std::string axis_last_error(std::size_t axis) const;

  // Clock (CLOCK_MONOTONIC ns) of the response deadline, the node timeouts and every SDO time
  // (transfer timeout, pacing, retries, how long a request waits); tests replace it together with
  // the virtual bus' clock.
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

  // ---- Node lifecycle (canio_nmt.cpp) ----
  struct NodeTrack {  // cycle thread
    uint8_t node = 0;
    uint32_t heartbeat_ms = 0;
    int64_t consumer_ns = 0;            // heartbeat consumer timeout
    int64_t heartbeat_deadline_ns = 0;  // 0: not watched now
    bool start_due = false;             // send NMT Start at the next step
    bool started = false;               // Start sent since the last configuration
    int64_t start_sent_ns = 0;
    int64_t next_start_ns = 0;
    int64_t start_backoff_ns = 0;
    bool trust_by_heartbeat = false;  // after a bus restart: OPERATIONAL heartbeat suffices
    // Identity (canio_identity.cpp): expected objects (bit f: kIdentityFields[f]), checked before
    // the node's modules are configured, again after each boot-up and silence.
    uint8_t identity_mask = 0;
    std::array<uint32_t, 5> identity_expected{};
    bool identity_due = false;
    NodeIdentityState identity_state = NodeIdentityState::Unchecked;
    int64_t identity_backoff_ns = 0;
    // The check in progress.
    uint8_t id_read = 0, id_unreadable = 0;
    std::array<uint32_t, 5> id_found{};
    std::error_code id_error;
  };
  [[nodiscard]] std::size_t node_index(uint8_t node) const noexcept;
  // Frames on the node port: SDO answers, boot-up / heartbeat, EMCY.
  void drain_node_port(int64_t now) noexcept;
  void on_error_control(std::size_t k, NmtState state, int64_t now) noexcept;
  void on_emcy(std::size_t k, const Emcy& e, int64_t now) noexcept;
  // The node's axes go down and are configured (`fresh`: anew) or checked again.
  void node_down(std::size_t k, bool fresh, int64_t now) noexcept;
  void step_nmt(int64_t now) noexcept;
  void node_configured(std::size_t axis, int64_t now) noexcept;
  void push_event(const CanioNodeEvent& e) noexcept;
  [[nodiscard]] bool bus_filtered(const CanFrame& f) noexcept;

  // ---- Register access over SDO (canio_sdo.cpp): one job at a time — a module's configuration,
  // its check after a silence, or one of the daemon's requests — made of expedited transfers.
  enum class SdoJobKind : uint8_t { None, Configure, Check, Request, Identity, Info };
  enum class SdoStage : uint8_t { Write, ReadBack, Heartbeat, Rescan, Read };
  struct SdoJob {
    SdoJobKind kind = SdoJobKind::None;
    SdoStage stage = SdoStage::Write;
    uint16_t axis = 0;
    uint8_t step = 0;     // Configure: start-up write; Check: register read
    bool verify = false;  // Request writes: read back
    RegisterRequest request{};
    // Configure, in start-up order, then the additional-information channels' EnDatInfoCmd0N.
    std::array<RegisterWrite, kStartupWriteCount + kInfoChannels> writes{};
    uint8_t write_count = 0;
    // Info: EnDatInfoOK (step 0), then each configured channel's EnDatInfo0N.
    uint8_t info_ok = 0;
    std::array<uint16_t, kInfoChannels> info{};
    // Configure: the first read-back that differed (it does not stop the configuration).
    std::error_code mismatch;
    uint16_t mismatch_reg = 0;
    uint32_t mismatch_value = 0;
    // Configure: the first write the module refused (an abort); the others are written all the
    // same.
    std::error_code refused;
    uint16_t refused_reg = 0;  // 0: the heartbeat producer time (0x1017)
    uint32_t refused_value = 0;
    bool heartbeat_done = false;
  };
  // The transfer a job needs next.
  struct SdoOp {
    uint16_t reg = 0;
    uint8_t size = 1;
    bool write = false;
    uint32_t value = 0;
    uint16_t index = 0;  // != 0: this node object instead of the register's (0x1017)
    uint8_t subindex = 0;
  };
  struct AxisSdo {             // cycle thread
    bool reconfigure = false;  // configure the module (or check it after a silence)
    int64_t info_due_ns = 0;   // the next read of the additional-information channels
    bool info_ready = false;   // a completed read for the next exchange to hand over
    uint8_t info_ok = 0;
    std::array<uint16_t, kInfoChannels> info{};
    bool fresh = false;  // configure anew, no check (the node announced a reset)
    int64_t retry_at_ns = 0;
    int64_t backoff_ns = 0;   // unconfigurable: next retry after this (doubling, bounded)
    unsigned definitive = 0;  // configurations in a row that got a definitive wrong answer
  };
  struct Deferred {  // a request for an axis being configured
    RegisterRequest request{};
    int64_t since_ns = 0;
  };
  // What status shows as an axis' last SDO error, written by the cycle thread in fixed fields
  // (no string there) under a sequence counter, composed into words by axis_last_error().
  enum class NoteKind : uint8_t { None, Configuring, Rescan, Checking, Refused, Heartbeat };
  struct SdoNote {
    NoteKind kind = NoteKind::None;
    uint8_t unverified_after = 0;  // > 0: the axis went up unverified after so many answers
    uint16_t reg = 0;
    uint32_t value = 0;
    std::error_code error;
  };
  class NoteCell {
   public:
    void store(const SdoNote& note) noexcept;  // one writer
    [[nodiscard]] SdoNote load() const noexcept;

   private:
    std::atomic<uint32_t> seq_{0};
    std::atomic<uint8_t> kind_{0}, unverified_after_{0};
    std::atomic<uint16_t> reg_{0};
    std::atomic<uint32_t> value_{0};
    std::atomic<int> code_{0};
    std::atomic<const std::error_category*> category_{nullptr};
  };

  void step_sdo(int64_t now) noexcept;
  [[nodiscard]] bool next_job(int64_t now) noexcept;
  void start_configure(std::size_t axis) noexcept;
  void start_request(const RegisterRequest& request) noexcept;
  // The daemon's next request, from the register path: started, answered at once (no such axis),
  // kept for its axis being configured, or left queued while that waiting room is full.
  Offer offer(const RegisterRequest& request) noexcept override;
  [[nodiscard]] SdoOp current_op() const noexcept;
  // Starts the job's next transfer; false when it ended without one (no SDO object).
  [[nodiscard]] bool issue(int64_t now) noexcept;
  void transfer_done(int64_t now, std::error_code ec, uint32_t value, uint8_t size) noexcept;
  void configure_step_done(int64_t now, std::error_code ec, uint32_t value) noexcept;
  void check_step_done(int64_t now, std::error_code ec, uint32_t value, uint8_t size) noexcept;
  void request_step_done(std::error_code ec, uint32_t value) noexcept;
  // The additional-information channels (canio_sdo.cpp): the register the Info job's step reads,
  // and the step's answer.
  [[nodiscard]] static uint16_t info_step_reg(uint8_t step) noexcept;
  void info_step_done(std::error_code ec, uint32_t value) noexcept;
  void after_writes(int64_t now) noexcept;
  void unconfigurable(int64_t now, uint16_t reg, uint32_t value, std::error_code ec) noexcept;
  void finish_configure(int64_t now, std::error_code ec, bool completed) noexcept;
  void mark_configured(std::size_t axis, int64_t now) noexcept;
  void answer(const RegisterRequest& request, std::error_code ec, uint32_t value) noexcept;
  void note(std::size_t axis, const SdoNote& n) noexcept { notes_[axis].store(n); }
  // ---- Node identity (canio_identity.cpp) ----
  // Starts the identity check of axis' node; false when the node has nothing to check.
  [[nodiscard]] bool start_identity(std::size_t axis) noexcept;
  void identity_step_done(int64_t now, std::error_code ec, uint32_t value) noexcept;
  void finish_identity(int64_t now) noexcept;
  void publish_identity(std::size_t k) noexcept;
  [[nodiscard]] bool identity_refused(std::size_t k) const noexcept;

  CanioBusOptions options_;
  std::unique_ptr<CanPort> cycle_port_;
  std::unique_ptr<CanPort> sdo_port_;
  SdoMapping sdo_mapping_;
  ByteOrder order_ = ByteOrder::Little;
  std::vector<ObjectRoute> routes_;  // sorted by id; fixed after construction
  std::vector<Track> track_;
  std::unique_ptr<CanioAxisCounters[]> axis_counters_;
  CanioBusCounters counters_;
  std::array<CanFrame, 64> rx_{};
  int64_t sync_tx_ns_ = 0;  // this cycle's window
  int64_t deadline_ns_ = 0;
  std::atomic<BusState> state_{BusState::Down};
  bool bus_off_raised_ = false;  // the bus-off incident of this bus-off is raised (cycle thread)
  Clock clock_;
  std::string start_error_;

  // Register access (cycle thread; the queues are the register path's, BusDriver::registers()).
  ExpeditedSdoClient sdo_client_;
  std::array<CanFrame, 16> sdo_rx_{};
  SdoJob job_;
  std::vector<AxisSdo> axis_sdo_;
  std::array<Deferred, kSdoQueueDepth> deferred_{};
  std::size_t deferred_count_ = 0;
  int64_t offer_now_ = 0;      // the step's time while the register path offers a request
  int64_t next_sdo_ns_ = 0;    // pacing: no transfer starts before
  std::size_t next_axis_ = 0;  // round robin over the axes to configure
  std::unique_ptr<NoteCell[]> notes_;

  // Node lifecycle (cycle thread, but for the counters and the event queue's other end).
  std::vector<NodeTrack> nodes_;
  std::vector<uint16_t> axis_node_;  // axis → index into nodes_
  std::unique_ptr<CanioNodeCounters[]> node_counters_;
  SpscQueue<CanioNodeEvent, kNodeEventQueueDepth> events_;
  bool bus_was_down_ = false;  // the last cycle found the controller bus-off / down

  mutable std::mutex info_mutex_;  // normal threads only
  CanInterfaceInfo info_;
};

}  // namespace ds1928::canio

namespace std {
template <>
struct is_error_code_enum<ds1928::canio::CanioBusError> : true_type {};
}  // namespace std
