// Structured log records for the journal: events an operator filters by (a node reset, bus-off,
// a configuration or identification failure, start and stop) carry journal fields beside their
// text when the daemon logs to journald — a stable MESSAGE_ID per event kind, DS1928_NODE,
// DS1928_AXIS, DS1928_BUS, DS1928_REASON — so `journalctl DS1928_NODE=1` selects one node.
// On the console the record is the same text line as before.
//
// The records go through the same asynchronous spdlog logger as every other line (order kept,
// no I/O on the caller's thread): the fields travel in front of the text, framed by control
// characters that no log text contains, and the journald sink (JournalSink) takes them apart.
// The cycle thread still never logs.
#pragma once

#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <array>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>

namespace ds1928::control {

enum class LogEvent : uint8_t {
  None = 0,  // no MESSAGE_ID
  Started,
  Stopping,
  StartFailed,
  BusState,
  NodeReset,
  NodeOperational,
  BusOff,
  ConfigurationFailed,
  IdentificationFailed,
  NodeSilent,
  Incident,         // the flight recorder wrote the frames around an incident to a file
  ModuleErrorBits,  // an axis' ErrorInfo / EnDatError / EnDatWarning bits changed
};
inline constexpr std::size_t kLogEventCount = 13;

// The 128-bit id (32 lowercase hex digits, journald's form) of an event kind; empty for None.
// Stable: tools and saved journalctl filters depend on them (docs/operations.md).
[[nodiscard]] std::string_view message_id(LogEvent e) noexcept;
// "node_reset", ... (documentation, tests).
[[nodiscard]] std::string_view event_name(LogEvent e) noexcept;

struct EventFields {
  EventFields(LogEvent event_, std::string_view bus_ = {}, int node_ = -1, int axis_ = -1,
              std::string_view reason_ = {}, std::string_view incident_ = {},
              std::string_view incident_file_ = {}) noexcept
      : event(event_),
        node(node_),
        axis(axis_),
        bus(bus_),
        reason(reason_),
        incident(incident_),
        incident_file(incident_file_) {}

  LogEvent event = LogEvent::None;
  int node = -1;                   // DS1928_NODE (POWERLINK node id / CAN-I/O node), -1: none
  int axis = -1;                   // DS1928_AXIS (axis index), -1: none
  std::string_view bus;            // DS1928_BUS (powerlink, canio, simulated), empty: none
  std::string_view reason;         // DS1928_REASON, empty: none
  std::string_view incident;       // DS1928_INCIDENT (the incident's kind), empty: none
  std::string_view incident_file;  // DS1928_INCIDENT_FILE (its pcapng file), empty: none
};

// Logs `text` at `level` with the fields when the journald sink is in use, else the text alone.
void log_event(spdlog::level::level_enum level, const EventFields& fields, std::string_view text);

// Set by setup_logging(): whether records carry fields to the sink.
void set_structured_logging(bool on) noexcept;

// The journald sink: one sd_journal_sendv() per record with MESSAGE, PRIORITY,
// SYSLOG_IDENTIFIER and the record's fields. (spdlog's systemd sink has no per-record fields.)
class JournalSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  explicit JournalSink(std::string identifier) : identifier_(std::move(identifier)) {}

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override;
  void flush_() override {}

 private:
  std::string identifier_;
};

// What log_event() puts in front of the text, and what the sink takes apart (tests).
inline constexpr char kFieldMark = '\x1f';  // before each NAME=value
inline constexpr char kTextMark = '\x1e';   // between the fields and the text
struct SplitRecord {
  std::array<std::string_view, 8> fields{};  // NAME=value
  std::size_t field_count = 0;
  std::string_view text;
};
[[nodiscard]] SplitRecord split_record(std::string_view payload) noexcept;

}  // namespace ds1928::control
