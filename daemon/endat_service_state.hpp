// EnDatService's per-axis state and its jobs, shared by the files that implement the service by
// concern: endat_service.cpp (life cycle), endat_service_jobs.cpp (the job queue),
// endat_service_poll.cpp (polling the tunnel), endat_service_status.cpp (the status register
// reads), endat_service_ident.cpp (the two identification strategies), endat_service_json.cpp
// (replies) and endat_service_errors.cpp (error naming). Private to the daemon.
#pragma once

#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "endat_service.hpp"

namespace ds1928 {

struct EnDatService::Job {
  JobId id = 0;
  JobKind kind = JobKind::Single;
  std::vector<endat::Request> steps;
  std::size_t next = 0;  // step to send next
  JobResult result;
  Done done;
  bool cancelled = false;
};

struct EnDatService::Axis {
  // The command in the tunnel. A reply belongs to it: there is never more than one.
  struct InFlight {
    std::unique_ptr<Job> job;
    endat::RequestMessage message;
    uint32_t tag = 0;
    Clock::time_point deadline{};
    bool submitted = false;        // handed to CycleWork (false: its queue was full, retry)
    bool sent = false;             // Flatstream confirmed delivery
    bool maybe_delivered = false;  // Flatstream: unconfirmed / timeout — a reply may still come
    unsigned resends = 0;
  };

  std::deque<std::unique_ptr<Job>> queue;
  std::optional<InFlight> in_flight;
  // After a timeout the module may still answer the old command: nothing is sent until that
  // late reply arrived or the quiet period ended.
  bool awaiting_late_reply = false;
  Clock::time_point quiet_until{};
  std::chrono::milliseconds timeout{2000};
  Counters counters;
  LatencyHistogram latency;

  // Identification.
  std::optional<endat::Identification> ident;
  endat::ManufacturerWords words{};
  std::string ident_state = "pending";  // pending, reading, ok, failed
  std::string ident_source;             // registers, flatstream
  std::error_code ident_error;
  bool identifying = false;
  std::vector<std::function<void(std::error_code)>> ident_waiters;

  // Status words from the 1 s register reads.
  std::optional<uint16_t> endat_error;
  std::optional<uint16_t> endat_warning;
  std::error_code status_error;
  unsigned status_pending = 0;
};

// An error of the transport (the tunnel, not the encoder): the service's own category.
[[nodiscard]] inline bool is_transport_error(std::error_code ec) noexcept {
  return ec.category() == endat_service_category();
}

}  // namespace ds1928
