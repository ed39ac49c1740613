// Simulated CAN-I/O node: a bus controller with simulated X20DS1928 modules in function model 254
// on a CanPort (SocketCAN or the virtual test bus), a strict CANopen node (CiA 301): it boots
// pre-operational and announces it with a boot-up message (0x700 + node, 0x00), sends and takes
// no process data until NMT Start, honours Stop / Enter Pre-Operational / Reset Node / Reset
// Communication, and produces a heartbeat once the master sets object 0x1017. In OPERATIONAL it
// answers the master's SYNC with every
// module's two input objects (without SYNC: a module's output object triggers its answer), takes
// the output objects, and serves expedited SDO (0x600 + node → 0x580 + node) on the register →
// index/subindex scheme the daemon uses. Single-threaded: the owner calls service() in a loop.
// Faults for tests: random loss of its frames, wrong lengths, foreign identifiers, silence, object
// 2 sent late, a reset by itself (brown-out: the modules' settings lost), a stalled acquisition
// (the same position and PosCycle resent), EMCY messages. The answers to a SYNC go out
// `sync_reaction_ns` after it (the bus controller's reaction); like a real controller the node
// sends its answers in order and never sends an answer to an older SYNC after it has queued the
// answers to a newer one (an object 2 still waiting when the next SYNC's answers are due is sent
// first).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include "can/can_port.hpp"
#include "canio/canio_options.hpp"
#include "canio/canopen_nmt.hpp"
#include "canio/sdo_expedited.hpp"
#include "sim/ds1928_module.hpp"
#include "sim/sim_options.hpp"
#include "x20ds1928/sdo_mapping.hpp"

namespace ds1928::sim {

struct CanioNodeModule {
  uint8_t slot = 1;
  CanioAxisIds ids;
  SimAxisConfig sim;
};

struct CanioNodeFaults {
  double drop = 0.0;                // probability of not sending an input object
  uint32_t wrong_length_every = 0;  // every n-th position object with 7 bytes (0: off)
  uint32_t unexpected_id = 0;       // also send a frame with this id per SYNC (0: off)
  bool answer_sdo = true;           // false: SDO requests are ignored (no acyclic access)
  double late_object2 = 0.0;        // probability that object 2 goes out late_object2_ns late
  int64_t late_object2_ns = 0;      // how late (after the node's reaction)
  // SDO: answer a 1-byte register read with 4 bytes (a peer that widens small registers).
  bool widen_sdo_reads = false;
  // SDO: configuration registers answer reads with 0x06010001 "write only": the FM254 register
  // table lists them with write access only (the strict reading, the default). false: they can
  // be read back (a test that needs a verified configuration asks for it).
  bool config_write_only = true;
  // SDO: this register answers with this CiA 301 abort code (0: off), on writes and/or reads.
  uint16_t abort_register = 0;
  uint32_t abort_code = 0;
  bool abort_on_write = true;
  bool abort_on_read = true;
  // NMT: the first n Start commands addressed to the node are lost (a node that misses them).
  uint32_t ignore_nmt_starts = 0;
  // SDO: upload responses say "size not indicated" (CiA 301 e = 1, s = 0; 4 data bytes).
  bool upload_size_not_indicated = false;
  uint64_t seed = 1;
};

// The bus controller's identity (CiA 301: 0x1000 device type, 0x1018/1..4 identity object),
// read-only. B&R's documents at hand do not say what an X20 CAN bus controller reports: the
// defaults are placeholders (ASSUMPTION, docs/canio.md §Node identity); canio_node_from_config()
// takes the identity canio.nodes[] expects where it is given.
struct CanioNodeIdentity {
  bool present = true;  // false: 0x1000 and 0x1018 do not exist (every read: abort 0x06020000)
  uint32_t device_type = 0x00000000;
  uint32_t vendor_id = 0x0000001A;  // B&R's, as docs/powerlink.md uses it (ASSUMPTION for CAN)
  uint32_t product_code = 0x00000001;
  uint32_t revision_no = 0x00010000;
  uint32_t serial_no = 0x00000001;
};

struct CanioNodeConfig {
  uint8_t node = 1;
  CanioNodeIdentity identity;
  std::vector<CanioNodeModule> modules;
  bool little_endian = true;
  bool sync_enabled = true;
  uint32_t sync_id = 0x080;
  std::map<uint16_t, std::pair<uint16_t, uint8_t>> sdo_overrides;
  CanioNodeFaults faults;
  // ASSUMPTION (docs/canio.md): the bus controller queues its answers this long after the SYNC's
  // end of frame (the stamp it received it with).
  int64_t sync_reaction_ns = 0;
  // CiA 301 strict: after its boot-up the node waits pre-operational for NMT Start. true: a bus
  // controller that starts by itself (CiA 302 "self-starting"): operational right after the
  // boot-up message.
  bool self_start = false;
  // Heartbeat producer time at power-up (object 0x1017, ms; 0: none until the master sets it).
  uint16_t heartbeat_ms = 0;
  // The node's clock (CLOCK_MONOTONIC ns; tests pass the virtual bus' fake clock). Empty: the
  // real CLOCK_MONOTONIC.
  std::function<int64_t()> clock;
};

// The node behind `node` of a configured bus: the axes on that node become its modules
// (simulated.axes[i] describes axes[i]).
[[nodiscard]] CanioNodeConfig canio_node_from_config(const CanioBusConfig& canio,
                                                     std::span<const AxisConfig> axes,
                                                     const SimulatedBusConfig& simulated,
                                                     uint8_t node);

struct CanioNodeCounters {
  uint64_t syncs = 0;
  uint64_t outputs = 0;
  uint64_t inputs_sent = 0;  // input objects sent
  uint64_t inputs_dropped = 0;
  uint64_t inputs_late = 0;  // objects 2 sent late (fault)
  uint64_t send_failures = 0;
  uint64_t sdo_requests = 0;
  uint64_t sdo_aborts = 0;
  uint64_t nmt_commands = 0;  // NMT commands addressed to this node
  uint64_t boot_ups = 0;      // boot-up messages sent (power-up, resets)
  uint64_t heartbeats = 0;
  uint64_t emcys = 0;
  uint64_t stalled_answers = 0;          // answers that repeated the last position (stall fault)
  uint64_t ignored_not_operational = 0;  // SYNC / output objects ignored outside OPERATIONAL
};

class CanioNode {
 public:
  CanioNode(CanioNodeConfig config, canio::CanPort& port);
  ~CanioNode();
  CanioNode(const CanioNode&) = delete;
  CanioNode& operator=(const CanioNode&) = delete;

  // Filters on the port (NMT, SYNC, output objects, SDO requests), then the boot-up message.
  [[nodiscard]] std::error_code open();
  // Sends the answers that are due, then handles what arrives until `deadline_ns` or the next
  // answer is due (one receive call; a deadline in the past polls). Returns the frames handled.
  std::size_t service(int64_t deadline_ns);
  // Sends the answers due by now (without receiving).
  void send_due();
  // When the next queued answer is due (INT64_MAX: none).
  [[nodiscard]] int64_t next_due_ns() const noexcept;

  // Power-cycle (Reset Node): every module back to its bus-controller defaults (EnDat disabled),
  // the heartbeat time back to its power-up value, boot-up message, pre-operational (operational
  // with self_start). Owner's thread.
  void power_up();
  // Any thread: the node resets by itself at its next service() (brown-out, watchdog) — the
  // object store is lost, as power_up().
  void request_reset() noexcept { reset_requested_.store(true); }
  // Any thread: while true the modules' acquisition is stalled — every answer repeats the last
  // position and PosCycle sent.
  void set_stalled(bool stalled) noexcept { stalled_.store(stalled); }
  // Owner's thread: another bus controller on the cable from now on (a node replaced: call
  // power_up() or request_reset() for its boot-up).
  void set_identity(const CanioNodeIdentity& identity) noexcept { config_.identity = identity; }
  // Any thread: the node sends this EMCY at its next service().
  void request_emcy(uint16_t error_code, uint8_t error_register,
                    std::array<uint8_t, 5> vendor = {}) noexcept;
  [[nodiscard]] canio::NmtState nmt_state() const noexcept { return nmt_.load(); }
  [[nodiscard]] uint16_t heartbeat_ms() const noexcept { return heartbeat_ms_; }
  // No answers at all while true (a node that lost power or its bus connection).
  void set_silent(bool silent) noexcept { silent_.store(silent); }
  // The next `n` SDO requests go unanswered, the objects are still sent (an SDO server that
  // lags behind after a restart).
  void drop_sdo_requests(uint32_t n) noexcept { sdo_drops_.store(n); }

  [[nodiscard]] std::size_t module_count() const noexcept { return modules_.size(); }
  [[nodiscard]] Ds1928Module& module(std::size_t i) { return *modules_.at(i); }
  [[nodiscard]] const CanioNodeCounters& counters() const noexcept { return counters_; }
  [[nodiscard]] const CanioNodeConfig& config() const noexcept { return config_; }

  // Test hook: module i's inputs as sent in answer to the SYNC received at `sync_time_ns`.
  std::function<void(std::size_t module, int64_t sync_time_ns, const ModuleInputs&)> on_inputs;
  // Log hook: the SYNC count (1, 2, ... as received) → module i's position and PosCycle sent.
  std::function<void(uint64_t sync_count, std::size_t module, const ModuleInputs&)> on_answer;

 private:
  void answer(std::size_t module, int64_t time_ns);
  void serve_sdo(const canio::CanFrame& f);
  // 0x1000 / 0x1018: true when the request addressed them (`reply` filled, abort codes given).
  bool serve_identity(const canio::SdoMessage& request, canio::SdoMessage& reply,
                      uint32_t& abort_code) const;
  void on_nmt(const canio::NmtMessage& m);
  // Boot-up message, pre-operational (operational with self_start).
  void boot();
  void service_faults();
  void send(const canio::CanFrame& f);
  void queue(const canio::CanFrame& f, int64_t due_ns);
  [[nodiscard]] int64_t now() const;

  CanioNodeConfig config_;
  canio::CanPort& port_;
  SdoMapping mapping_;
  std::vector<std::unique_ptr<Ds1928Module>> modules_;
  CanioNodeCounters counters_;
  std::mt19937_64 rng_;
  std::atomic<bool> silent_{false};  // set from another thread (tests, the simulator main)
  std::atomic<uint32_t> sdo_drops_{0};
  std::atomic<canio::NmtState> nmt_{canio::NmtState::PreOperational};
  std::atomic<bool> reset_requested_{false};
  std::atomic<bool> stalled_{false};
  std::atomic<bool> emcy_requested_{false};
  std::atomic<uint64_t> emcy_word_{0};  // error code | register << 16 | vendor << 24
  uint16_t heartbeat_ms_ = 0;           // object 0x1017
  int64_t next_heartbeat_ns_ = 0;
  std::vector<ModuleInputs> last_inputs_;  // per module: the last answer (stall fault)
  std::vector<bool> have_last_;
  uint32_t starts_ignored_ = 0;
  uint64_t position_objects_ = 0;
  // Answers waiting for their time, in the order they go out (fixed size: no allocation).
  struct Queued {
    canio::CanFrame frame;
    int64_t due_ns = 0;
  };
  std::array<Queued, 64> tx_{};
  std::size_t tx_head_ = 0;
  std::size_t tx_count_ = 0;
};

}  // namespace ds1928::sim
