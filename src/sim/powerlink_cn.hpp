// Simulated POWERLINK bus controller (Controlled Node) hosting simulated X20DS1928 modules.
//
// PowerlinkCn is the pure protocol core (Lely style): frames in through receive(frame, now),
// time through tick(now), frames out through the send callback. It runs in-process against the
// Managing Node in unit tests, or on a raw socket through PowerlinkCnLoop.
//
// NMT (EPSG DS 301 CN states, powerlink.md §5):
//   power-up → INITIALISING → RESET_APPLICATION → RESET_COMMUNICATION → NOT_ACTIVE
//   NOT_ACTIVE --SoA/SoC--> PRE_OPERATIONAL_1 --SoC--> PRE_OPERATIONAL_2
//   --NMTEnableReadyToOperate--> READY_TO_OPERATE --NMTStartNode--> OPERATIONAL
//   loss of SoC in PRE_OPERATIONAL_2 and above → PRE_OPERATIONAL_1; reset commands → the
//   matching RESET_* state → NOT_ACTIVE.
// Process image: powerlink/process_image.hpp's layout from the modules' MTUs and offset
// overrides (the same make_layout() the MN uses), reported as PollInSize/PollOutSize in the
// IdentResponse; after an MN wrote a PDO mapping and NMTResetConfiguration, the registers where
// that mapping puts them (powerlink/pdo_image.hpp, take_mapping()). NetTime: a module's NetTime at
// instant t is low32(RelativeTime of the last SoC + offset) plus the time elapsed since that SoC
// arrived — the relation the MN maps PosTime back with.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <span>
#include <string_view>
#include <vector>

#include "powerlink/error_signalling.hpp"
#include "powerlink/frames.hpp"
#include "powerlink/link.hpp"
#include "powerlink/pdo_image.hpp"
#include "powerlink/powerlink_options.hpp"
#include "powerlink/process_image.hpp"
#include "powerlink/sdo.hpp"
#include "sim/cn_object_dictionary.hpp"
#include "sim/ds1928_module.hpp"
#include "sim/nettime_anchor.hpp"
#include "sim/sim_options.hpp"
#include "x20ds1928/sdo_mapping.hpp"

namespace ds1928::sim {

struct PowerlinkCnModuleConfig {
  uint8_t slot = 1;
  SimAxisConfig sim;
  uint8_t input_mtu = 7;   // Rx bytes room in the PRes (fixed PDO mapping of the bus controller)
  uint8_t output_mtu = 7;  // Tx bytes room in the PReq
  std::optional<uint16_t> pres_offset;  // AxisConfig::pres_offset; unset = default layout
  std::optional<uint16_t> preq_offset;  // AxisConfig::preq_offset
};

// Fault injection. Probabilities are per PRes.
struct PowerlinkCnFaults {
  double drop_pres = 0.0;   // PRes not sent
  double delay_pres = 0.0;  // PRes sent `delay_pres_ns` late
  int64_t delay_pres_ns = 0;
  int pres_size_delta = 0;  // PRes payload this many bytes longer (or shorter)
  // PRes with RD = 0 also in OPERATIONAL: the node's application has no valid TPDO data (EPSG
  // DS 301); an MN must not take its inputs.
  bool pres_not_ready = false;
  uint64_t seed = 1;
};

// The PDO mapping the bus controller has of its own (0x1A00/0x1600, readable by SDO and taken at
// every reset unless an MN writes another): none (mapping disabled, the packed image), the packed
// image as a mapping, or rearranged: PosCycle before PositionLW in each module's block, or every
// register followed by a byte no object is mapped to (and the outputs AckErrorInfo first).
enum class OwnMapping : uint8_t { kNone, kPacked, kPosCycleFirst, kGap };
struct OwnPdoMapping {
  std::vector<powerlink::PdoMapEntry> tpdo;
  std::vector<powerlink::PdoMapEntry> rpdo;
};
// The entries of `style` for the modules of `layout` (packed) through `scheme`.
[[nodiscard]] OwnPdoMapping own_pdo_mapping(OwnMapping style,
                                            const powerlink::NodeImageLayout& layout,
                                            const PdoObjectScheme& scheme);

// A CN whose PRes comes from software (a user-space stack on a PC): each PRes leaves after a
// log-normal delay — median `pres_latency_median_ns`, shape `pres_latency_sigma` (0.6 gives
// p99 ≈ 4 × median, p99.99 ≈ 9 × median: a long tail), capped at `pres_latency_max_ns` — and
// not before `ready_after_soc_ns` after the cycle's SoC (the stack is still busy with the SoC's
// work). All zero: the PRes leaves at once, as from the bus controller's hardware.
struct PowerlinkCnResponse {
  int64_t pres_latency_median_ns = 0;
  double pres_latency_sigma = 0.6;
  int64_t pres_latency_max_ns = 2'000'000;
  int64_t ready_after_soc_ns = 0;
};

struct PowerlinkCnConfig {
  uint8_t node_id = 1;
  powerlink::MacAddress mac{0x02, 0x00, 0x00, 0x00, 0x19, 0x28};
  // Identification (IdentResponse, NMT_DeviceType and NMT_IdentityObject).
  uint32_t device_type = 0x00000191;  // DS 401 generic I/O
  uint32_t vendor_id = 0x0000001A;
  uint32_t product_code = 0x00001928;
  uint32_t revision_no = 0x00010000;
  uint32_t serial_no = 1;
  uint32_t response_time_ns = 10'000;  // reported PRes response time
  std::vector<PowerlinkCnModuleConfig> modules{PowerlinkCnModuleConfig{}};
  SdoMapping::Overrides sdo_overrides;
  int64_t nettime_offset_us = 0;
  // No SoC for this many learned cycle periods (at least soc_timeout_min_ns) = loss of SoC.
  uint32_t soc_loss_periods = 5;
  int64_t soc_timeout_min_ns = 5'000'000;
  uint32_t loss_of_preq_threshold = 15;  // DLL threshold counter (+8 per event, −1 per cycle)
  int64_t power_off_ns = 300'000'000;    // how long a power cycle keeps the node silent
  PowerlinkCnFaults faults;
  PowerlinkCnResponse response;
  // PollResponse Chaining (EPSG DS 302-C): advertised in the IdentResponse's feature flags; an MN
  // may then switch the node to PRC with SyncRequests (powerlink_cn_prc.cpp).
  bool prc_capable = true;
  // The bus controller's object scheme: an MN that writes a PDO mapping (0x1A00/0x1600) names
  // the modules' registers by it; after NMTResetConfiguration the node sends and takes each
  // register where that mapping puts it (powerlink/pdo_image.hpp). Without a mapping: packed.
  PdoObjectScheme object_scheme;
  OwnMapping own_mapping = OwnMapping::kNone;
};

struct PowerlinkCnStats {
  uint64_t soc = 0;
  uint64_t preq = 0;
  uint64_t pres_sent = 0;
  uint64_t pres_dropped = 0;
  uint64_t pres_delayed = 0;      // by the delay fault or the software response model
  uint64_t pres_not_ready = 0;    // PRes sent in OPERATIONAL with RD = 0 (the fault)
  uint64_t mappings_taken = 0;    // PDO mappings written by an MN and in use
  uint64_t mappings_refused = 0;  // ... that do not bind to the modules (packed image kept)
  uint64_t soa = 0;
  uint64_t asnd_sent = 0;
  uint64_t nmt_commands = 0;
  uint64_t sdo_frames_in = 0;
  uint64_t loss_of_soc = 0;
  uint64_t loss_of_preq = 0;
  uint64_t power_cycles = 0;
  uint64_t nmt_requests_sent = 0;
  uint64_t resets = 0;
  uint64_t errors_raised = 0;    // error entries queued (raise_error, DLL errors)
  uint64_t bad_frames = 0;       // rejected by the codec
  uint64_t short_frames = 0;     // accepted although shorter than 60 bytes (unpadded sender)
  uint64_t sync_requests = 0;    // SyncRequests to this node (answered with a SyncResponse)
  uint64_t pres_mn = 0;          // PResMN seen while in PRC mode (each answered with the PRes)
  uint64_t pres_mn_outputs = 0;  // ... whose outputs (RD = 1) the modules took
  uint64_t prc_fallbacks = 0;    // PRC mode left for PReq/PRes: no PResMN within the fallback time
  // Multiplexed (MultiplCycleCnt > 1): PReqs out of the slot this node was first polled in
  // (its place in the multiplexed cycle, from the SoC's MC flag); each counts as loss of PReq.
  uint64_t preq_out_of_slot = 0;
  // Spans in which the simulator's own thread was not run by its host (note_own_stall): not
  // counted as silence on the wire.
  uint64_t own_stalls = 0;
  int64_t own_stall_max_ns = 0;
};

class PowerlinkCn {
 public:
  using FrameSink = std::function<void(std::span<const uint8_t> frame)>;
  using StateListener =
      std::function<void(powerlink::NmtState from, powerlink::NmtState to, int64_t now_ns)>;

  PowerlinkCn(const PowerlinkCnConfig& config, FrameSink send);
  ~PowerlinkCn();
  PowerlinkCn(const PowerlinkCn&) = delete;
  PowerlinkCn& operator=(const PowerlinkCn&) = delete;

  // A received Ethernet frame (any POWERLINK frame on the wire; the CN picks what is its own).
  void receive(std::span<const uint8_t> frame, int64_t now_ns) noexcept;
  // Timeouts (loss of SoC, power-on), delayed PRes, module ticks. Call at least every ms.
  void tick(int64_t now_ns) noexcept;
  // Earliest instant tick() has work to do (delayed PRes, end of power-off); INT64_MAX if none.
  [[nodiscard]] int64_t next_deadline_ns() const noexcept;
  // The simulator's own thread was not run from `from_ns` to `to_ns` by its host (the vCPU
  // stopped; not a task of this machine running instead). A CN in its own hardware never stops,
  // and on a test machine that stops both the MN and the simulator the wire did not go silent:
  // that span does not count toward the loss of SoC. Silence the simulator was there to see
  // still counts in full.
  void note_own_stall(int64_t from_ns, int64_t to_ns) noexcept;

  // Fault injection: the node loses power now and boots again after config.power_off_ns.
  void power_cycle(int64_t now_ns) noexcept;
  void set_faults(const PowerlinkCnFaults& faults) noexcept;
  // The node asks the MN for its own reset: announced with priority 7 (PRIO_NMT_REQUEST) in its
  // PRes/StatusResponse, sent as an NMTRequest (NMTResetNode, target = itself) when the MN invites
  // it with NMTRequestInvite. A power cycle forgets it.
  void request_own_reset() noexcept { nmt_request_pending_ = true; }
  // An error the node reports (a module error, a test's injection): queued in its emergency
  // queue as a vendor-specific "occurred" entry stamped with the node's NetTime, signalled to
  // the MN by toggling EN (powerlink/error_signalling.hpp). A reset empties the queue.
  void raise_error(uint16_t code, const std::array<uint8_t, 8>& info, int64_t now_ns) noexcept;
  [[nodiscard]] const powerlink::CnErrorSignalling& error_signalling() const noexcept {
    return errsig_;
  }

  [[nodiscard]] powerlink::NmtState nmt_state() const noexcept { return state_; }
  [[nodiscard]] uint8_t node_id() const noexcept { return config_.node_id; }
  [[nodiscard]] const PowerlinkCnStats& stats() const noexcept { return stats_; }
  // The communication objects an MN writes (0x1006, 0x1020, 0x1F98...), as they are now.
  [[nodiscard]] const CnObjectDictionary& communication_objects() const noexcept { return comm_; }
  // The image in use: from the PDO mapping an MN wrote, else packed.
  [[nodiscard]] const powerlink::NodeImageLayout& layout() const noexcept {
    return by_mapping_ ? mapped_layout_ : layout_;
  }
  [[nodiscard]] bool image_by_mapping() const noexcept { return by_mapping_; }
  // PRC: the modules' outputs from the PResMN, where the RPDO an MN wrote for it
  // (PDO_RxCommParam NodeID_U8 = 240) puts them; nullptr when none was written.
  [[nodiscard]] const powerlink::NodeImageLayout* pres_mn_layout() const noexcept {
    return outputs_from_pres_mn_ ? &pres_mn_layout_ : nullptr;
  }
  [[nodiscard]] std::size_t module_count() const noexcept { return modules_.size(); }
  [[nodiscard]] Ds1928Module& module(std::size_t i) noexcept { return *modules_[i].module; }
  // Learned SoC period (0 until two SoCs arrived).
  [[nodiscard]] int64_t cycle_period_ns() const noexcept { return period_ns_; }
  // PRC: in PRC mode (PRes after the PResMN instead of after a PReq), and the PRes time assigned.
  [[nodiscard]] bool prc_mode() const noexcept { return prc_mode_; }
  [[nodiscard]] uint32_t pres_time_first_ns() const noexcept { return pres_time_first_ns_; }
  void set_state_listener(StateListener listener) { listener_ = std::move(listener); }

 private:
  struct HostedModule {
    uint8_t slot = 1;
    std::unique_ptr<Ds1928Module> module;
    const powerlink::ModuleMapping* mapping = nullptr;
    const powerlink::ModuleMapping* pres_mn_mapping = nullptr;  // its outputs in the PResMN
  };
  class Objects;

  // NMT as a table of small handlers.
  struct StateHandler {
    powerlink::NmtState state;
    void (PowerlinkCn::*on_soc)(const powerlink::Soc&, int64_t);
    void (PowerlinkCn::*on_preq)(const powerlink::PReq&, int64_t);
    void (PowerlinkCn::*on_soa)(const powerlink::SoA&, int64_t);
  };
  [[nodiscard]] const StateHandler& handler() const noexcept;
  void enter(powerlink::NmtState next, int64_t now_ns) noexcept;
  void boot(int64_t now_ns) noexcept;
  // Binds a mapping an MN wrote through the node's object scheme (counted taken or refused).
  [[nodiscard]] bool bind_mapping(const powerlink::PdoMappingLists& lists,
                                  powerlink::NodeImageLayout& out) noexcept;
  void take_mapping() noexcept;  // the modules' registers where the PDO mapping says
  void reset(powerlink::NmtCommandId command, int64_t now_ns) noexcept;

  // Handlers.
  void soc_activate(const powerlink::Soc& soc, int64_t now_ns) noexcept;
  void soc_pre_op1(const powerlink::Soc& soc, int64_t now_ns) noexcept;
  void soc_cycling(const powerlink::Soc& soc, int64_t now_ns) noexcept;
  void preq_ignore(const powerlink::PReq&, int64_t) noexcept {}
  void preq_answer(const powerlink::PReq& preq, int64_t now_ns) noexcept;
  void soa_activate(const powerlink::SoA& soa, int64_t now_ns) noexcept;
  void soa_answer(const powerlink::SoA& soa, int64_t now_ns) noexcept;
  void soa_ignore(const powerlink::SoA&, int64_t) noexcept {}

  void on_asnd(const powerlink::Frame& frame, int64_t now_ns) noexcept;
  // PollResponse Chaining (powerlink_cn_prc.cpp).
  void on_sync_request(std::span<const uint8_t> frame, int64_t now_ns) noexcept;
  void on_foreign_sync_response(uint8_t src_node, int64_t now_ns) noexcept;
  void on_pres_mn(const powerlink::PRes& pres, int64_t now_ns) noexcept;
  void check_slot(int64_t now_ns) noexcept;
  void count_loss_of_preq(int64_t now_ns) noexcept;
  void check_prc_fallback(int64_t now_ns) noexcept;
  void leave_prc() noexcept;
  void note_polled() noexcept;  // a PReq (or, in PRC mode, a PResMN) polled this node
  void on_nmt_command(uint8_t command, int64_t now_ns) noexcept;
  void note_soc_timing(const powerlink::Soc& soc, int64_t now_ns) noexcept;
  void tick_modules(int64_t now_ns) noexcept;
  [[nodiscard]] uint64_t net_time_us_at(int64_t now_ns) const noexcept;
  // `offset_ns`: PRC's PRes time after the PResMN (0: answer a PReq at once).
  void send_pres(int64_t now_ns, int64_t offset_ns = 0) noexcept;
  void send_ident_response() noexcept;
  void send_status_response() noexcept;
  void queue_async(std::span<const uint8_t> frame) noexcept;
  [[nodiscard]] uint8_t request_count() const noexcept;
  [[nodiscard]] uint8_t request_priority() const noexcept;
  void log_error(uint16_t code, int64_t now_ns) noexcept;
  void queue_error(uint16_t type, uint16_t code, const std::array<uint8_t, 8>& info,
                   int64_t now_ns) noexcept;
  void emit(std::span<const uint8_t> frame) noexcept;

  PowerlinkCnConfig config_;
  // Delay of this PRes from the software response model (0 without one).
  [[nodiscard]] int64_t software_response_delay(int64_t now_ns) noexcept;

  FrameSink send_;
  StateListener listener_;
  powerlink::NmtState state_ = powerlink::NmtState::kOff;
  std::vector<HostedModule> modules_;
  std::vector<powerlink::ModuleSpec> specs_;
  powerlink::NodeImageLayout layout_;         // packed (or at the configured offsets)
  powerlink::NodeImageLayout mapped_layout_;  // from a PDO mapping an MN wrote
  bool by_mapping_ = false;
  powerlink::NodeImageLayout pres_mn_layout_;  // outputs from the PResMN (PRC)
  bool outputs_from_pres_mn_ = false;
  SdoMapping mapping_;
  CnObjectDictionary comm_;  // communication objects an MN configures
  std::unique_ptr<Objects> objects_;
  std::unique_ptr<powerlink::SdoServer> sdo_;
  PowerlinkCnStats stats_;
  bool nmt_request_pending_ = false;
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> uniform_{0.0, 1.0};
  std::normal_distribution<double> normal_{0.0, 1.0};

  // Cycle timing.
  int64_t last_soc_ns_ = 0;
  int64_t unobserved_since_soc_ns_ = 0;  // of the time since the last SoC, the own stalls' part
  int64_t period_ns_ = 0;
  uint64_t soc_relative_us_ = 0;
  bool have_soc_ = false;
  // The module's NetTime: CLOCK_MONOTONIC minus this anchor's offset.
  NetTimeAnchor net_anchor_;
  // The DLL configuration taken from the objects when the node last passed RESET_CONFIGURATION
  // (every reset does; EPSG DS 301: objects written later wait for the next one): PRes/PReq
  // payload sizes (0x1F98/5, /4 or the PDO mappings) and MultiplCycleCnt (0x1F98/7).
  struct DllConfig {
    uint16_t pres_size = 0;
    uint16_t preq_size = 0;
    uint8_t multiplexed_cycle_count = 0;
  } dll_;
  // Loss of PReq: cycles since the last PReq against the interval of 0x1F98/7 (1 when it is 0).
  uint32_t cycles_since_preq_ = 0;
  // The multiplexed cycle as the SoCs' MC flag shows it: the cycle's place in it (0 = the first,
  // -1 before MC first toggled) and the place of this node's slot (-1 until first polled).
  bool mc_seen_ = false;
  bool last_mc_ = false;
  int mux_pos_ = -1;
  int mux_slot_pos_ = -1;
  uint32_t preq_interval_ = 0;  // 0 = not polled since the reset
  uint32_t loss_of_preq_counter_ = 0;
  // Power.
  bool powered_ = true;
  int64_t power_on_at_ns_ = 0;
  // PollResponse Chaining.
  bool prc_mode_ = false;
  uint32_t pres_time_first_ns_ = 0;
  uint32_t pres_fallback_timeout_ns_ = 0;
  bool pres_mn_since_soc_ = false;  // a PResMN came since the last SoC
  int64_t prc_missing_ns_ = 0;      // cycles without a PResMN, in a row
  uint8_t sync_prev_node_ = 0;      // target of the last SyncRequest to another node ...
  int64_t sync_prev_ns_ = 0;        // ... and when it arrived
  uint32_t sync_node_number_ = 0;
  uint32_t sync_delay_ns_ = 0;
  // Delayed PRes.
  bool pres_pending_ = false;
  int64_t pres_due_ns_ = 0;
  std::size_t pres_pending_len_ = 0;
  std::array<uint8_t, powerlink::kMaxFrameSize> pres_frame_{};
  // Async send queue (SDO answers), sent one per UnspecifiedInvite.
  static constexpr std::size_t kAsyncSlots = 8;
  std::array<std::array<uint8_t, powerlink::kMaxFrameSize>, kAsyncSlots> async_frames_{};
  std::array<std::size_t, kAsyncSlots> async_len_{};
  std::size_t async_head_ = 0;
  std::size_t async_count_ = 0;
  // Error signalling: ER/EC handshake, EN/EA, the emergency queue the StatusResponse carries.
  powerlink::CnErrorSignalling errsig_;
  // PReq payload buffer for the outputs and frame scratch.
  std::array<uint8_t, powerlink::kMaxFrameSize> tx_{};
};

// Drives a set of PowerlinkCn from one link. Polls with the link's receive in the cycle's busy
// phase and sleeps in its idle phase: after a SoA it sleeps until `guard_ns` before the next
// SoC is due (a SCHED_FIFO task that spins all the time is throttled by the kernel and starves
// the other core's work), and blocks in wait_readable() when no SoC rhythm is known (silence, or
// an MN's reduced cycle, whose SoAs need not be periodic).
class PowerlinkCnLoop {
 public:
  struct Options {
    int64_t guard_ns = 80'000;  // start polling this long before the next SoC is due
    int64_t idle_wait_ns = 1'000'000;
    // The thread's run-queue wait so far in ns (the kernel's schedstat): a stall of the loop is
    // its host's only for the part the kernel did not count as waiting for a CPU of this
    // machine. Empty: no stall is the host's (every silence counts).
    std::function<int64_t()> run_queue_wait_ns;
    // The loop back from a wait later than this after its deadline (or the frame's stamp) =
    // a stall.
    int64_t own_stall_min_ns = 500'000;
  };
  PowerlinkCnLoop(powerlink::Link& link, std::function<bool(int64_t)> wait_readable,
                  std::span<PowerlinkCn* const> nodes, Options options);
  // One pass: receives what is there (polling until the phase's deadline) and ticks the nodes.
  // Returns false on a link error that is not a timeout.
  bool run_once() noexcept;

  // Arrival rhythm of one frame type (SoC in full cycles, SoA in the reduced cycle): what the
  // loop sleeps by. A gap of more than 4 periods is a pause (the MN's host stalled, the link was
  // gone), not a new period — learned as one, the loop would sleep through the next cycles and
  // answer every PResMN late until the average came back. Two such gaps in a row are: the MN
  // runs a longer cycle now.
  struct Rhythm {
    int64_t last = 0;
    int64_t period = 0;
    uint32_t pauses = 0;  // gaps of more than 4 periods in a row
    void note(int64_t t) noexcept;
    [[nodiscard]] bool valid(int64_t now) const noexcept {
      return period > 0 && now - last < 3 * period;
    }
  };

 private:
  [[nodiscard]] int64_t next_cycle_start(int64_t now) const noexcept;
  // `now` read after a wait that should have ended by `due`: later means the thread was stopped
  // meanwhile; the host's part of that goes to the nodes.
  void check_own_stall(int64_t due, int64_t now) noexcept;

  powerlink::Link& link_;
  std::function<bool(int64_t)> wait_readable_;
  std::vector<PowerlinkCn*> nodes_;
  Options options_;
  Rhythm soc_;
  Rhythm soa_;
  bool cycle_done_ = false;          // SoA seen: idle phase until the next cycle start
  int64_t run_queue_wait_mark_ = 0;  // run_queue_wait_ns() at this pass' start
  std::array<uint8_t, powerlink::kMaxFrameSize> rx_{};
};

}  // namespace ds1928::sim
