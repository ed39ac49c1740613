// The flight recorder's incidents (docs/operations.md "Flight recorder"): every capture point of
// the bus always records into a ring of its own (capture/flight_ring.hpp,
// flight_recorder.ring_bytes split between them); on an incident this service waits for the tail
// (after_ms), then writes the frames of [event - before_s, event + after_ms] that the rings still
// hold to one pcapng file in the incident directory (incident_store.hpp), logs it with the file in
// the journal field DS1928_INCIDENT_FILE, and lists it for `ds1928ctl incidents`.
//
// Incidents come from the cycle thread through the IncidentSink (a bus driver's
// raise_incident(), the cycle work's axis transitions and overrun bursts), and from the normal
// thread (the bus kind's watch events, `ds1928ctl incident mark`). An incident of the same kind,
// node and axis as one whose tail is still running joins it (one file, `count` raised).
// Normal thread only, except sink(), which the cycle thread feeds.
#pragma once

#include <array>
#include <boost/asio/io_context.hpp>
#include <deque>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "capture/tap.hpp"
#include "config/config.hpp"
#include "control/control_server.hpp"
#include "core/incident.hpp"
#include "incident_store.hpp"
#include "metrics/exposition.hpp"

namespace ds1928 {

struct IncidentRecord {
  uint64_t number = 0;      // in this run, from 1
  int64_t time_ns = 0;      // CLOCK_MONOTONIC of the event
  int64_t realtime_ns = 0;  // the same instant on CLOCK_REALTIME
  IncidentKind kind = IncidentKind::Manual;
  int node = -1;
  int axis = -1;
  std::string text;
  uint32_t count = 1;  // incidents that joined this one while its tail ran
  std::string file;    // full path; empty: not written (see `error`)
  std::string error;   // why no file
  uint64_t frames = 0;
  uint64_t bytes = 0;
  int64_t first_frame_ns = 0;  // CLOCK_REALTIME of the oldest frame written (0: none)
};

class IncidentService {
 public:
  // `taps`: the bus' capture points (they outlive the service); each gets its flight ring now,
  // before the cycle thread starts. `bus_name`: DS1928_BUS of the journal records.
  IncidentService(const DaemonConfig& config, std::span<capture::Tap* const> taps,
                  std::string bus_name);

  // Normal thread, once before the cycle thread starts: the incident directory. Errors are
  // logged; the recorder then keeps its rings but writes no file.
  void open();
  [[nodiscard]] IncidentSink& sink() noexcept { return sink_; }
  [[nodiscard]] bool enabled() const noexcept { return enabled_; }
  // The directory files go to ("" when none).
  [[nodiscard]] std::string dir() const { return store_ ? store_->dir() : std::string(); }

  // Normal thread: an incident seen now (`time_ns` 0) or at `time_ns` (CLOCK_MONOTONIC).
  void raise(IncidentKind kind, int node, int axis, std::string text, int64_t time_ns = 0);
  // Normal thread, every tick: takes the sink's incidents, writes those whose tail is over.
  // `now_ns` 0: now. `flush`: write every pending incident now (the daemon stops).
  void poll(int64_t now_ns = 0, bool flush = false);

  void register_commands(control::Server& server);
  [[nodiscard]] nlohmann::json list_json() const;
  [[nodiscard]] nlohmann::json status_json() const;
  void append_metrics(metrics::Exposition& out) const;
  // Written (or attempted) incidents of this run, oldest first (at most max_files kept).
  [[nodiscard]] const std::deque<IncidentRecord>& records() const noexcept { return records_; }

 private:
  void write(IncidentRecord r);
  [[nodiscard]] std::vector<uint8_t> build_file(const IncidentRecord& r, int64_t mono_to_real,
                                                uint64_t& frames, int64_t& first_frame_ns) const;

  const DaemonConfig& config_;
  const FlightRecorderConfig& fr_;
  std::vector<capture::Tap*> taps_;
  std::string bus_name_;
  bool enabled_ = false;
  IncidentSink sink_;
  std::unique_ptr<IncidentStore> store_;
  std::vector<IncidentRecord> pending_;  // tail still running
  std::deque<IncidentRecord> records_;
  uint64_t next_number_ = 1;
  std::array<uint64_t, kIncidentKindCount> raised_{};
  uint64_t joined_ = 0;
  uint64_t written_ = 0;
  uint64_t write_failures_ = 0;
  uint64_t pending_dropped_ = 0;
};

}  // namespace ds1928
