// EnDat commands of the daemon (normal thread, Boost.Asio): per axis a FIFO of commands from the
// control socket, at most one in the axis' Flatstream tunnel at a time, per-command timeouts,
// cancellation, write verification by read-back, the encoder identification at start and the
// periodic EnDatError/EnDatWarning read. docs/endat-commands.md explains the rules.
//
//   EnDatService endat(io, work, registers, config);
//   endat.register_commands(server);   // endat-reset, endat-read-param, ...
//   endat.start();                      // identification, poll timer
//   ... status["axes"][i]["endat"] = endat.status_json(i);
//   endat.stop();                       // before the io_context / CycleWork go away
//
// Everything runs on the io_context's thread; nothing here is called from the cycle thread.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "config/config.hpp"
#include "control/control_server.hpp"
#include "control/peer_privilege.hpp"
#include "core/bucket_histogram.hpp"
#include "cycle_work.hpp"
#include "endat/command.hpp"
#include "endat/ident.hpp"
#include "register_client.hpp"

namespace ds1928 {

// Failures the service adds to the codec's endat::Errc.
// Bucket bounds of the EnDat command latency (metrics endpoint), ns: a command crosses the
// Flatstream tunnel in a few cycles, a slow one (EEPROM write) takes tens of ms.
inline constexpr std::array<int64_t, 12> kEnDatLatencyBoundsNs{
    1'000'000,   2'000'000,   5'000'000,   10'000'000,   20'000'000,   50'000'000,
    100'000'000, 200'000'000, 500'000'000, 1000'000'000, 2000'000'000, 5000'000'000};

enum class EnDatServiceErrc : int {
  timeout = 1,     // no reply within AxisConfig::command_timeout_ms
  not_delivered,   // Flatstream gave up before the module had the whole command (not executed)
  busy,            // the axis' command queue is full
  write_rejected,  // the read-back differs from the written value (protected area)
  cancelled,       // the client went away
  stopped,         // the service stopped before the command ran
  no_such_axis,
  identification_unavailable,  // neither the registers nor Flatstream reads gave a valid
                               // identification
};
[[nodiscard]] const std::error_category& endat_service_category() noexcept;
[[nodiscard]] std::error_code make_error_code(EnDatServiceErrc e) noexcept;

// The socket's error code (snake_case) for an error of the service or the codec:
// timeout, not_delivered, busy, write_rejected, echo_mismatch, truncated_reply, oversized_reply,
// module_crc_error, module_no_response, module_not_supported, module_malformed_request,
// module_wire_echo_mismatch, module_failure, requires_endat22, bad_argument, ...
[[nodiscard]] std::string_view endat_error_code_name(std::error_code ec) noexcept;

// Identification as JSON (raw words are added by the caller where wanted).
[[nodiscard]] nlohmann::json identification_json(const endat::Identification& ident);

class EnDatService {
 public:
  // How a job's steps are run and judged.
  enum class JobKind : uint8_t {
    Single,       // one command; its outcome is the job's
    WriteVerify,  // write, then read the same parameter back (write_rejected on a difference)
    Sequence,     // reads in order (dump, identification); a module failure of one step is kept
                  // in that step and the next runs; a transport failure (timeout, not
                  // delivered, busy) ends the job
  };
  struct StepResult {
    endat::Request request;
    std::error_code error;
    endat::Reply reply;
  };
  struct JobResult {
    std::error_code error;  // the job's outcome (see JobKind)
    std::string detail;     // human detail for `error` (e.g. what was read back)
    std::vector<StepResult> steps;
  };
  using JobId = uint64_t;
  using Done = std::function<void(const JobResult&)>;

  // Commands waiting per axis (not counting the one in flight) before `busy`.
  static constexpr std::size_t kQueueDepth = 16;
  // Retries of a command Flatstream reports as certainly not executed.
  static constexpr unsigned kMaxResends = 2;

  EnDatService(boost::asio::io_context& io, CycleWork& work, RegisterClient& registers,
               const DaemonConfig& config);
  ~EnDatService();
  EnDatService(const EnDatService&) = delete;
  EnDatService& operator=(const EnDatService&) = delete;

  // Starts the poll timer, the identification of every axis and the 1 s status reads.
  void start();
  // Stops the timers; queued and in-flight jobs complete with `stopped`. Idempotent.
  void stop();

  // Per-axis view for `status`: identification, EnDatError/EnDatWarning, command counters.
  [[nodiscard]] nlohmann::json status_json(std::size_t axis) const;
  // endat-reset, endat-ack, endat-read-param, endat-write-param, endat-read-block,
  // endat-write-block, endat-read-info, endat-ident, endat-dump (docs/socket-protocol.md).
  void register_commands(control::Server& server);

  // Queues a job for an axis. `done` runs exactly once on the io_context's thread, unless the
  // job is cancelled first. Returns 0 (and calls `done` at once with the error) when the axis
  // does not exist or its queue is full.
  JobId submit(std::size_t axis, JobKind kind, std::vector<endat::Request> steps, Done done);
  // The client went away: a queued job is dropped; an in-flight one finishes its current
  // command, whose reply is discarded, and runs no further step. `done` is not called.
  void cancel(JobId id);

  // Identification of an axis, once known.
  [[nodiscard]] const std::optional<endat::Identification>& identification(std::size_t axis) const;
  // Called after every identification of an axis (at start and on refresh), with the result:
  // the expected topology compares it (topology.hpp). Normal thread.
  using IdentifiedHook =
      std::function<void(std::size_t axis, std::error_code, const endat::Identification*)>;
  void set_identified_hook(IdentifiedHook hook) { identified_hook_ = std::move(hook); }
  // Why the bus gives an axis no data (BusService::axis_cause), for the log of a failed
  // identification: the bus' cause says more than "the command did not reach the module".
  using CauseSource = std::function<std::string(std::size_t axis)>;
  void set_cause_source(CauseSource source) { cause_source_ = std::move(source); }
  // The `endat-ident` reply body: identification, raw words 4..47 with names, status words.
  [[nodiscard]] nlohmann::json identification_reply(std::size_t axis) const;
  [[nodiscard]] bool identifying(std::size_t axis) const;
  // Reads the identification again (registers, else Flatstream); `done` gets the outcome.
  void refresh_identification(std::size_t axis, std::function<void(std::error_code)> done);

  // EnDatAck (§11.6.2.3): writes `bits` (kEnDatAckAcknowledge, kEnDatAckRescan) to the module
  // register and reads it back until the module cleared them — it clears a bit once it ran the
  // bit's algorithm (re-read the identification, acknowledged the encoder's errors). `done`
  // gets the outcome: the write's error, EnDatServiceErrc::timeout when the bits stay set for
  // kEnDatAckTimeout, or success with `confirmed` false when the register cannot be read back
  // (the write went through; the completion is then not observable).
  static constexpr uint8_t kEnDatAckAcknowledge = 0x01;
  static constexpr uint8_t kEnDatAckRescan = 0x02;
  static constexpr std::chrono::milliseconds kEnDatAckTimeout{3000};
  using AckDone = std::function<void(std::error_code, bool confirmed, unsigned reads)>;
  void endat_ack_register(std::size_t axis, uint8_t bits, AckDone done);

  // Peer check for the privileged commands (tests replace it; default peer_is_privileged).
  void set_privilege_check(std::function<bool(const control::PeerCredentials&)> check);

  // Figures of one axis (tests, benchmark).
  struct Counters {
    uint64_t commands_sent = 0;  // Flatstream messages submitted (resends included)
    uint64_t replies = 0;        // replies matched to the command in flight
    uint64_t timeouts = 0;
    uint64_t resends = 0;
    uint64_t late_replies = 0;        // replies after a timeout, discarded
    uint64_t unexpected_replies = 0;  // replies with no command in flight, discarded
    uint64_t discarded_replies = 0;   // replies of cancelled commands
    uint64_t jobs_done = 0;
    uint64_t jobs_failed = 0;
    uint64_t jobs_cancelled = 0;
  };
  [[nodiscard]] Counters counters(std::size_t axis) const;
  // Command latency (first submission to the tunnel → matching reply) of one axis.
  using LatencyHistogram = BucketHistogram<kEnDatLatencyBoundsNs>;
  [[nodiscard]] const LatencyHistogram& command_latency(std::size_t axis) const;

 private:
  struct Job;
  struct Axis;
  using Clock = std::chrono::steady_clock;

  void arm_poll();
  void arm_status();
  void poll();
  void poll_axis(std::size_t index, Clock::time_point now);
  void dispatch(std::size_t index, Clock::time_point now);
  void transmit(std::size_t index, Clock::time_point now);
  void finish_step(std::size_t index, std::error_code error, const endat::Reply& reply);
  void complete_job(Axis& axis, std::unique_ptr<Job> job);
  void read_status_registers();
  void start_identification(std::size_t index);
  void identify_by_registers(std::size_t index, unsigned attempt);
  void identify_by_flatstream(std::size_t index);
  void identification_done(std::size_t index, std::error_code error);
  void poll_endat_ack(std::size_t index, uint8_t bits, Clock::time_point deadline, unsigned reads,
                      AckDone done);
  [[nodiscard]] bool may_change_encoder(const control::Request& request) const;

  boost::asio::io_context& io_;
  CycleWork& work_;
  IdentifiedHook identified_hook_;
  CauseSource cause_source_;
  RegisterClient& registers_;
  const DaemonConfig& config_;
  boost::asio::steady_timer poll_timer_;
  boost::asio::steady_timer status_timer_;
  std::chrono::microseconds poll_period_;
  std::vector<std::unique_ptr<Axis>> axes_;
  std::function<bool(const control::PeerCredentials&)> privileged_;
  JobId next_job_ = 1;
  uint32_t next_tag_ = 1;
  bool running_ = false;
  // Guards callbacks that outlive the service (RegisterClient, socket replies).
  std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
};

}  // namespace ds1928

template <>
struct std::is_error_code_enum<ds1928::EnDatServiceErrc> : std::true_type {};
