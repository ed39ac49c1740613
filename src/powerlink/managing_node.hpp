// The POWERLINK Managing Node as a pure protocol core: it decides what every frame of a cycle
// carries and reacts to what comes back, but does no I/O and reads no clock. The driver
// (PowerlinkBus) owns the timing: it asks for the SoC, the PReq of each isochronous CN, the SoA
// and the MN's own ASnd, sends them, and hands every received frame and every timeout back.
//
// NMT boot of each CN (docs/powerlink.md §Boot) is a table of small state handlers:
//   Identify → WaitPreOp2 → Configure (SDO) → WaitReadyToOperate → WaitOperational → Operational
//   and Reset (after loss / power-cycle / timeout) → Identify again.
// Everything is preallocated at construction; the per-cycle calls never allocate.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/axis_config.hpp"
#include "core/register_path.hpp"
#include "powerlink/concise_dcf.hpp"
#include "powerlink/error_signalling.hpp"
#include "powerlink/frames.hpp"
#include "powerlink/powerlink_options.hpp"
#include "powerlink/process_image.hpp"
#include "powerlink/sdo.hpp"
#include "x20ds1928/sdo_mapping.hpp"

namespace ds1928::powerlink {

enum class CnBootState : uint8_t {
  kIdentify,    // IdentRequests until an IdentResponse matches the configuration
  kWaitPreOp2,  // StatusRequests until the CN reports PRE_OPERATIONAL_2
  kConfigure,   // in the isochronous phase; SDO writes of the module settings
  // NMTResetConfiguration sent after objects were written (EPSG DS 301: the CN takes them on
  // re-entering its boot); out of the isochronous phase, identified again after reset_wait.
  kResetConfiguration,
  kWaitReadyToOperate,  // NMTEnableReadyToOperate sent
  kWaitOperational,     // NMTStartNode sent
  kOperational,
  kReset,  // NMTResetNode sent; waits before identifying again
};
[[nodiscard]] std::string_view to_string(CnBootState s) noexcept;

// DLL error threshold counter: +8 per cycle with the error, −1 per cycle without; fires (and
// restarts at 0) when it reaches the threshold. Threshold 0 disables it.
struct DllCounter {
  uint32_t value = 0;
  uint32_t events = 0;  // cycles with the error
  uint32_t fired = 0;   // threshold reached
  [[nodiscard]] bool step(bool error, uint32_t threshold) noexcept;
};

// An object of the CN's configuration (boot step "configure") the CN refused or did not answer.
struct ObjectAccessFailure {
  uint16_t index = 0;
  uint8_t subindex = 0;
  bool read = false;      // identity read (else a write)
  std::error_code error;  // an SDO abort (sdo_abort_category, value = abort code) or SdoError
};
inline constexpr std::size_t kMaxReportedObjectFailures = 8;
inline constexpr std::size_t kMaxReportedErrorEntries = 8;

// The identity object that did not match (0x1000/0 device type, 0x1018/1..4).
struct IdentityMismatch {
  uint16_t index = 0;
  uint8_t subindex = 0;
  uint32_t expected = 0;
  uint32_t found = 0;
  bool unreadable = false;  // the read failed: `found` is meaningless
};

// "0x1C14/0 write: SDO abort 0x06090030: ..." / "0x1018/2 (product code): expected 0x00001928,
// found 0x00002928" — for status and the log (normal thread; allocates).
[[nodiscard]] std::string describe(const ObjectAccessFailure& f);
[[nodiscard]] std::string describe(const IdentityMismatch& m);

// Where a CN's process image comes from (docs/powerlink.md §Process image from the PDO mapping).
enum class ImageSource : uint8_t {
  kPacked,          // packed blocks (layout packed, or auto and the CN maps no TPDO)
  kWrittenMapping,  // the mapping the MN writes (its concise DCF or sdo_writes)
  kReadMapping,     // the CN's own mapping, read by SDO at boot
  kRefused,         // the CN's own mapping lacks a register or has a bad entry: no axis is fed
};
[[nodiscard]] std::string_view to_string(ImageSource s) noexcept;
inline constexpr std::size_t kMaxPdoMapEntries = 254;  // per mapping (DS 301: sub 1..254)

struct CnStatus {
  uint8_t node = 0;
  CnBootState boot = CnBootState::kIdentify;
  NmtState nmt = NmtState::kNotActive;  // last reported by the CN
  bool in_isochronous = false;
  bool identified = false;
  MacAddress mac{};
  uint32_t vendor_id = 0;
  uint32_t product_code = 0;
  uint16_t preq_size = 0;  // payload sizes in use
  uint16_t pres_size = 0;
  DllCounter loss_of_pres;
  uint32_t loss_of_pres_threshold = 0;  // in effect (0x1C09; 0 = disabled)
  DllCounter late_pres;
  uint32_t pres_received = 0;
  // PRes received before this cycle's PReq to the CN: the late answer to an earlier PReq
  // (frames carry no cycle number), dropped instead of being taken as this cycle's inputs.
  uint32_t stale_pres_dropped = 0;
  uint32_t pres_size_mismatches = 0;  // PRes payload size differed from pres_size
  // PRes with RD = 0 from a CN that reports OPERATIONAL: its TPDO data is not ready (EPSG DS 301),
  // so its inputs are not taken, and the CN's axes are not published valid from them.
  uint32_t pres_not_ready = 0;
  bool pres_ready = false;  // RD of the last PRes
  uint16_t last_pres_size = 0;
  uint32_t status_error_entries = 0;  // error entries fetched from the CN (new ones only)
  uint16_t last_error_code = 0;       // code of the last such entry
  // The last kMaxReportedErrorEntries of them, oldest first.
  std::array<ErrorEntry, kMaxReportedErrorEntries> error_entries{};
  std::size_t error_entry_count = 0;
  uint64_t static_error_bits = 0;  // of the last StatusResponse
  uint32_t boots = 0;              // times the CN reached OPERATIONAL
  // NMTResetConfiguration sent after the boot step "configure" wrote objects (not a reset).
  uint32_t configuration_resets = 0;
  // IdentResponses after NMTResetConfiguration whose configuration date/time (0x1020) was not the
  // expected one (0x1F26/0x1F27): the CN lost what was written; the download was repeated.
  uint32_t configuration_not_verified = 0;
  uint32_t resets = 0;  // NMTResetNode sent
  uint32_t sdo_errors = 0;
  // PollResponse Chaining (docs/powerlink.md §PollResponse Chaining): configured for it, in it
  // (PRes after the PResMN), polled with PReq/PRes because the CN lacks the PRC feature flag;
  // the PRes time assigned (ns after the PResMN's end), the SyncDelay the CN measured to its
  // predecessor, the relative propagation delay used, the CN's latency from its SyncResponse.
  bool prc_configured = false;
  bool prc = false;
  bool prc_fallback = false;
  uint32_t prc_pres_time_ns = 0;
  uint8_t prc_predecessor = 0;
  uint32_t prc_sync_delay_ns = 0;
  uint32_t prc_propagation_ns = 0;
  uint32_t prc_latency_ns = 0;
  // Its slot of the multiplexed cycle (NMT_MultiplCycleAssign: configured or assigned), 0 when
  // it is polled every cycle.
  uint8_t multiplex_slot = 0;
  // Where its outputs sit in the PResMN payload (bytes; prc_outputs_size 0: none there).
  uint16_t prc_outputs_offset = 0;
  uint16_t prc_outputs_size = 0;
  uint32_t sync_responses = 0;
  uint32_t nmt_requests = 0;          // NMTRequests received from the CN
  uint32_t nmt_requests_refused = 0;  // ... of them not served
  ImageSource image_source = ImageSource::kPacked;
  // kRefused: the binding's error and what it names ("slot 1: PosCycle (0x2001/4) is not
  // mapped"; fixed storage, the status is copied on the cycle thread).
  std::error_code image_error;
  std::array<char, 120> image_refusal{};
  std::error_code last_error;
  // Why the MN last reset the CN (kept when it boots again, unlike last_error).
  std::error_code last_reset_reason;
  // Boot step "configure": objects written (cumulative), and the failures of the last run (the
  // first kMaxReportedObjectFailures of them; object_failures counts all, cumulative).
  uint32_t objects_written = 0;
  uint32_t object_failures = 0;
  std::array<ObjectAccessFailure, kMaxReportedObjectFailures> last_failures{};
  std::size_t last_failure_count = 0;
  // Set when the identity check by SDO failed (kept until the identity matches).
  bool identity_mismatch = false;
  IdentityMismatch mismatch{};
  // Error signalling (powerlink/error_signalling.hpp): the handshake's state, how often it
  // completed and was given up, the CN's EN, the EA the MN acknowledges with (PReq, SoA), and
  // the EN toggles seen (each one a fetch of its entries).
  ErrSigState errsig = ErrSigState::kInitWaitEc1;
  uint32_t errsig_handshakes = 0;
  uint32_t errsig_gave_up = 0;
  bool exception_new = false;
  bool exception_acknowledge = false;
  uint32_t exceptions_signalled = 0;
};

struct MnCounters {
  uint64_t cycles = 0;
  DllCounter cycle_time_exceeded;
  uint32_t unexpected_frames = 0;  // frames that fit no expected slot
  uint32_t invalid_frames = 0;     // rejected by the codec
  uint32_t short_frames = 0;       // accepted although shorter than 60 bytes (unpadded sender)
  // IdentRequest/StatusRequest whose mandatory answer did not come within async_timeout.
  uint32_t async_timeouts = 0;
  // UnspecifiedInvite/NMTRequestInvite the CN let pass: it may legitimately have nothing to send
  // (its RS was already served, an SDO answer is not ready yet), so this is no error.
  uint32_t async_invites_unused = 0;
  // SoC, PReq or SoA of another MN (DS 301: one MN per segment). Seen while NOT_ACTIVE, it keeps
  // this MN there (foreign_mn_at_start); seen later, it is counted and named here.
  uint32_t foreign_mn_frames = 0;
  bool foreign_mn_at_start = false;
  MacAddress foreign_mn_mac{};
  MessageType foreign_mn_frame = MessageType::kSoC;
};

struct MnConfig {
  PowerlinkBusConfig bus;
  std::vector<AxisConfig> axes;  // modules per CN (node, slot) and their settings
  uint32_t cycle_us = 1000;
  MacAddress mac{};
};

class ManagingNode {
 public:
  // Throws std::system_error (MnError::kInvalidLayout, kModuleBlocksOverlap,
  // kModuleBlockOutsidePayload — what() names the node and slot(s) — or kNodeNotConfigured) on
  // a configuration that cannot run: called at start, never on the cycle path.
  explicit ManagingNode(const MnConfig& config);
  ~ManagingNode();
  ManagingNode(const ManagingNode&) = delete;
  ManagingNode& operator=(const ManagingNode&) = delete;

  // ---- One cycle, in this order ----
  // `now_ns`: the cycle's nominal start (CLOCK_MONOTONIC); boot timers run on it.
  void begin_cycle(int64_t now_ns) noexcept;
  // False in PRE_OPERATIONAL_1: a reduced cycle has no SoC and no PReq/PRes.
  [[nodiscard]] bool full_cycle() const noexcept;
  // The instant the SoC is sent (CLOCK_MONOTONIC, read just before build_soc) and the wall clock
  // for its NetTime. The CNs anchor their NetTime at the SoC's arrival, so RelativeTime must
  // describe when the SoC really leaves, not the nominal cycle start the cycle thread woke late
  // for. RelativeTime never goes backwards, whatever the clock says.
  void stamp_soc(int64_t send_ns, NetTime net_time) noexcept;
  [[nodiscard]] Result<std::size_t> build_soc(std::span<uint8_t> out) const noexcept;
  // Nodes to poll this cycle (continuous and the multiplexed ones due), in node order.
  [[nodiscard]] std::span<const uint8_t> isochronous_nodes() const noexcept;
  // PollResponse Chaining: the nodes that answer the PResMN this cycle (none: no PResMN), the
  // PResMN (marks them polled), and how long after the PResMN is sent their slot ends: the
  // PResMN's wire time, the last PRes time plus that PRes, and the longest PRes timeout of them.
  [[nodiscard]] std::span<const uint8_t> prc_nodes() const noexcept;
  [[nodiscard]] Result<std::size_t> build_pres_mn(std::span<uint8_t> out) noexcept;
  [[nodiscard]] int64_t prc_slot_ns() const noexcept { return prc_slot_ns_; }
  // PResMN payload in bytes: powerlink.pres_mn_size, or more when the chained nodes' outputs
  // (each at its prc_outputs_offset) need more.
  [[nodiscard]] uint16_t pres_mn_size() const noexcept { return pres_mn_size_; }
  // The driver wrote the whole output image of `node` for this cycle (after begin_cycle): only
  // then does its PReq, or the PResMN that carries its outputs, say RD = 1.
  void outputs_written(uint8_t node) noexcept;
  [[nodiscard]] Result<std::size_t> build_preq(uint8_t node, std::span<uint8_t> out) noexcept;
  [[nodiscard]] uint32_t pres_timeout_us(uint8_t node) const noexcept;
  // The PRes of `node` did not arrive in time.
  void on_pres_timeout(uint8_t node) noexcept;
  [[nodiscard]] Result<std::size_t> build_soa(std::span<uint8_t> out) noexcept;
  // After the SoA: the frame the MN invited itself to send (NMT command or SDO), if any.
  [[nodiscard]] Result<std::size_t> build_mn_asnd(std::span<uint8_t> out) noexcept;
  // True when the SoA invited a CN to send: the driver waits async_timeout for it.
  [[nodiscard]] bool awaiting_asnd() const noexcept { return awaiting_asnd_; }
  void on_async_timeout() noexcept;
  // Any received frame (PRes, ASnd, foreign traffic). Returns the parse error for statistics.
  std::error_code on_frame(std::span<const uint8_t> frame) noexcept;
  // `cycle_time_exceeded`: the driver's exchange ran past the period.
  void end_cycle(bool cycle_time_exceeded) noexcept;

  // ---- Process data (valid between begin_cycle and build_preq / after on_frame) ----
  // The outputs of `node` this cycle: its PReq payload, or for a chained node (PRC) its part of
  // the PResMN payload, laid out as its PReq would be (its layout's offsets apply to both).
  [[nodiscard]] std::span<uint8_t> preq_payload(uint8_t node) noexcept;
  [[nodiscard]] std::span<const uint8_t> pres_payload(uint8_t node) const noexcept;
  // The PRes of `node` arrived in this cycle with a usable size and RD = 1.
  [[nodiscard]] bool pres_fresh(uint8_t node) const noexcept;
  // The PRes of `node` arrived in this cycle (whatever its size and RD).
  [[nodiscard]] bool pres_seen(uint8_t node) const noexcept;
  [[nodiscard]] const NodeImageLayout* layout(uint8_t node) const noexcept;
  // Counts the changes of any node's layout (a CN's own mapping read and bound at boot): the
  // driver takes the layouts again when it moves.
  [[nodiscard]] uint32_t layouts_version() const noexcept { return layouts_version_; }
  // The PDO mapping the node's image was bound from (TPDO, RPDO): the mapping written to it or
  // read from it; empty when packed.
  [[nodiscard]] std::span<const PdoMapEntry> mapped_objects(uint8_t node, bool tpdo) const noexcept;
  // NetTime of this cycle's SoC (RelativeTime µs + offset), µs.
  [[nodiscard]] uint64_t net_time_us() const noexcept;
  [[nodiscard]] uint64_t relative_time_us() const noexcept { return relative_time_us_; }
  // CLOCK_MONOTONIC instant of the last stamp_soc(): the reference for net_time_us().
  [[nodiscard]] int64_t soc_time_ns() const noexcept { return soc_time_ns_; }

  // ---- Acyclic ----
  // A register request of the module in `slot` of CN `node` (its axis resolved by the caller),
  // as an SDO transfer. False when the node is unknown or its queue is full.
  [[nodiscard]] bool submit(uint8_t node, uint8_t slot, const RegisterRequest& request) noexcept;
  // True when submit() for `node` would find room: in the node's queue, and a result slot for
  // it (each request accepted holds one until its result is polled, so none is ever dropped,
  // however slowly results are taken and however many nodes have requests queued).
  [[nodiscard]] bool can_submit(uint8_t node) const noexcept;
  // One result per request submitted, in completion order.
  [[nodiscard]] bool poll(RegisterResult& out) noexcept;

  // ---- State ----
  [[nodiscard]] NmtState mn_state() const noexcept { return mn_state_; }
  // NOT_ACTIVE (MNWaitNotAct): the bus sends nothing and calls not_active_cycle() instead of
  // running a cycle; frames received meanwhile still go to on_frame().
  [[nodiscard]] bool not_active() const noexcept { return mn_state_ == NmtState::kNotActive; }
  void not_active_cycle() noexcept;
  [[nodiscard]] std::span<const CnStatus> nodes() const noexcept;
  [[nodiscard]] const CnStatus* node(uint8_t id) const noexcept;
  [[nodiscard]] const MnCounters& counters() const noexcept { return counters_; }
  // Every configured mandatory CN is OPERATIONAL.
  [[nodiscard]] bool all_operational() const noexcept;

 private:
  struct Cn;
  struct Handler;
  static const Handler kHandlers[];

  [[nodiscard]] NodeImageLayout image_layout(const PowerlinkNodeConfig& nc,
                                             std::span<const CdcEntry> written,
                                             std::span<const ModuleSpec> specs) const;
  // The CN's layout at start (packed or its written mapping) and whether its own is read at boot.
  void init_image(Cn& cn, std::span<const CdcEntry> written, std::span<const ModuleSpec> specs);
  Cn* find(uint8_t node) noexcept;
  const Cn* find(uint8_t node) const noexcept;
  void enter(Cn& cn, CnBootState state) noexcept;
  void reset_node(Cn& cn, std::error_code reason) noexcept;
  void queue_nmt(Cn& cn, NmtCommandId command) noexcept;
  void handle_pres(Cn& cn, const PRes& pres, std::span<const uint8_t> frame) noexcept;
  void handle_asnd(const FrameHeader& h, const Asnd& asnd) noexcept;
  void verify_configuration(Cn& cn, const IdentResponse& ident) noexcept;
  void handle_nmt_request(Cn& from, const NmtRequest& request) noexcept;
  void note_exception_new(Cn& cn, bool en) noexcept;
  void sync_errsig(Cn& cn) noexcept;
  void record_error_entries(Cn& cn, const StatusResponse& status) noexcept;
  void reported_state(Cn& cn, NmtState state) noexcept;
  void start_next_sdo(Cn& cn) noexcept;
  void sdo_done(Cn& cn, std::error_code ec, std::span<const uint8_t> data) noexcept;
  void start_object_op(Cn& cn) noexcept;  // the op at cn.object_next
  void object_done(Cn& cn, std::error_code ec, std::span<const uint8_t> data) noexcept;
  void start_mapping_read(Cn& cn) noexcept;
  void mapping_read_done(Cn& cn, std::error_code ec, std::span<const uint8_t> data) noexcept;
  void bind_read_mapping(Cn& cn) noexcept;
  void update_mn_state() noexcept;
  // PollResponse Chaining set-up (managing_node_prc.cpp).
  [[nodiscard]] bool uses_prc(const Cn& cn) const noexcept;
  [[nodiscard]] bool prc_setup_pending(const Cn& cn) const noexcept;
  [[nodiscard]] bool prc_wants_sync_request(const Cn& cn) const noexcept;
  [[nodiscard]] Result<std::size_t> build_prc_sync_request(Cn& cn, std::span<uint8_t> out) noexcept;
  void on_sync_response(Cn& cn, std::span<const uint8_t> data) noexcept;
  void on_sync_timeout(Cn& cn) noexcept;
  void prc_failed(Cn& cn) noexcept;
  [[nodiscard]] const Cn* prc_predecessor(const Cn& cn) const noexcept;
  [[nodiscard]] uint32_t prc_time_of(const Cn& cn) const noexcept;
  [[nodiscard]] uint16_t expected_pres_size(const Cn& cn) const noexcept;
  void update_prc_slot() noexcept;
  void place_prc_outputs();
  void assign_slots();
  [[nodiscard]] int64_t ms(uint32_t v) const noexcept {
    return static_cast<int64_t>(v) * 1'000'000;
  }

  // State handlers (one row each in kHandlers).
  void on_enter_identify(Cn& cn) noexcept;
  void on_enter_wait_preop2(Cn& cn) noexcept;
  void on_enter_configure(Cn& cn) noexcept;
  void on_enter_ready(Cn& cn) noexcept;
  void on_enter_wait_operational(Cn& cn) noexcept;
  void on_enter_operational(Cn& cn) noexcept;
  void on_enter_reset(Cn& cn) noexcept;
  void on_enter_reset_configuration(Cn& cn) noexcept;
  void on_state_identify(Cn& cn, NmtState s) noexcept;
  void on_state_wait_preop2(Cn& cn, NmtState s) noexcept;
  void on_state_configure(Cn& cn, NmtState s) noexcept;
  void on_state_ready(Cn& cn, NmtState s) noexcept;
  void on_state_wait_operational(Cn& cn, NmtState s) noexcept;
  void on_state_operational(Cn& cn, NmtState s) noexcept;
  void on_state_reset(Cn& cn, NmtState s) noexcept;
  void on_timeout_reset(Cn& cn) noexcept;
  void on_timeout_boot(Cn& cn) noexcept;

  MnConfig config_;
  SdoMapping mapping_;
  std::vector<std::unique_ptr<Cn>> cns_;
  std::vector<CnStatus> status_view_;
  std::vector<uint8_t> iso_list_;
  std::size_t iso_count_ = 0;
  std::vector<uint8_t> prc_list_;
  std::size_t prc_count_ = 0;
  int64_t prc_slot_ns_ = 0;
  std::array<uint8_t, kMaxIsoPayload> pres_mn_{};  // the PResMN payload: chained nodes' outputs
  uint16_t pres_mn_size_ = 0;
  NmtState mn_state_ = NmtState::kPreOperational1;
  int64_t now_ns_ = 0;
  int64_t start_ns_ = -1;
  int64_t mn_state_since_ns_ = 0;
  uint64_t relative_time_us_ = 0;
  uint32_t layouts_version_ = 0;
  uint64_t mux_cycle_len_ = 1;  // cycles of one multiplexed cycle (MultiplCycleCnt), 1: none
  bool mc_flag_ = false;        // SoC MC, toggled at the start of each multiplexed cycle
  int64_t soc_time_ns_ = 0;
  NetTime net_time_{};
  MnCounters counters_;
  // Async slot of this cycle.
  RequestedService soa_service_ = RequestedService::kNone;
  uint8_t soa_target_ = 0;
  bool awaiting_asnd_ = false;
  Cn* mn_asnd_from_ = nullptr;   // whose outbox the MN sends after the SoA
  Cn* prc_sync_from_ = nullptr;  // whose PRC set-up this cycle's SyncRequest serves
  std::size_t async_rr_ = 0;     // round-robin position among the CNs
  std::array<RegisterResult, kRegisterQueueDepth> results_{};
  std::size_t results_head_ = 0;
  std::size_t results_count_ = 0;
  // Register requests accepted whose result is not in results_ yet: queued, or the transfer under
  // way. Each holds a slot of results_ (can_submit()).
  [[nodiscard]] std::size_t requests_in_flight() const noexcept;
  // The result of a request accepted by submit(): its slot is free (can_submit()).
  void push_result(const RegisterResult& r) noexcept;
};

}  // namespace ds1928::powerlink
