#include <algorithm>
#include <cstdio>

#include "endat_service_state.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// Jobs

EnDatService::JobId EnDatService::submit(std::size_t index, JobKind kind,
                                         std::vector<endat::Request> steps, Done done) {
  JobResult refused;
  if (index >= axes_.size()) {
    refused.error = make_error_code(EnDatServiceErrc::no_such_axis);
  } else if (!running_) {
    refused.error = make_error_code(EnDatServiceErrc::stopped);
  } else if (axes_[index]->queue.size() >= kQueueDepth) {
    refused.error = make_error_code(EnDatServiceErrc::busy);
  }
  if (refused.error || steps.empty()) {
    if (done) done(refused);
    return 0;
  }
  auto job = std::make_unique<Job>();
  job->id = next_job_++;
  job->kind = kind;
  job->steps = std::move(steps);
  job->done = std::move(done);
  const JobId id = job->id;
  axes_[index]->queue.push_back(std::move(job));
  dispatch(index, Clock::now());
  return id;
}

void EnDatService::cancel(JobId id) {
  if (id == 0) return;
  for (auto& axis : axes_) {
    if (axis->in_flight && axis->in_flight->job && axis->in_flight->job->id == id) {
      axis->in_flight->job->cancelled = true;
      return;
    }
    auto it = std::find_if(axis->queue.begin(), axis->queue.end(),
                           [id](const auto& j) { return j->id == id; });
    if (it != axis->queue.end()) {
      axis->queue.erase(it);
      ++axis->counters.jobs_cancelled;
      return;
    }
  }
}

void EnDatService::dispatch(std::size_t index, Clock::time_point now) {
  Axis& a = *axes_[index];
  if (a.in_flight) {
    if (!a.in_flight->submitted) transmit(index, now);
    return;
  }
  if (a.awaiting_late_reply) {
    if (now < a.quiet_until) return;
    a.awaiting_late_reply = false;  // quiet period over: a reply now would be far too late
  }
  while (!a.in_flight && !a.queue.empty()) {
    std::unique_ptr<Job> job = std::move(a.queue.front());
    a.queue.pop_front();
    if (job->cancelled) {
      ++a.counters.jobs_cancelled;
      continue;
    }
    const endat::Request& request = job->steps[job->next];
    const endat::CommandSet set =
        a.ident ? a.ident->command_set
                : endat::CommandSet::EnDat22;  // unknown: let the module judge
    auto message = endat::encode_request(request, set);
    a.in_flight.emplace();
    a.in_flight->job = std::move(job);
    if (!message) {
      finish_step(index, message.error(), {});
      continue;
    }
    a.in_flight->message = *message;
    transmit(index, now);
  }
}

void EnDatService::transmit(std::size_t index, Clock::time_point now) {
  Axis& a = *axes_[index];
  auto& f = *a.in_flight;
  TunnelRequest request;
  request.kind = TunnelRequest::Kind::Message;
  request.tag = next_tag_++;
  if (next_tag_ == 0) next_tag_ = 1;
  request.size = f.message.size;
  std::copy_n(f.message.bytes.begin(), f.message.size, request.bytes.begin());
  if (!work_.submit_tunnel(index, request)) {
    f.submitted = false;  // the cycle thread's queue is full: next poll
    if (f.deadline == Clock::time_point{}) f.deadline = now + a.timeout;
    return;
  }
  f.submitted = true;
  f.tag = request.tag;
  f.sent = false;
  f.maybe_delivered = false;
  // The timeout runs from the first submission; resends do not extend it.
  if (f.deadline == Clock::time_point{}) f.deadline = now + a.timeout;
  ++a.counters.commands_sent;
}

void EnDatService::finish_step(std::size_t index, std::error_code error,
                               const endat::Reply& reply) {
  Axis& a = *axes_[index];
  std::unique_ptr<Job> job = std::move(a.in_flight->job);
  a.in_flight.reset();
  job->result.steps.push_back({job->steps[job->next], error, reply});
  ++job->next;
  bool more = job->next < job->steps.size() && !job->cancelled;
  if (error && (job->kind != JobKind::Sequence || is_transport_error(error))) more = false;
  if (error && job->kind == JobKind::Sequence && !is_transport_error(error) &&
      error == endat::Errc::requires_endat22)
    more = false;
  if (more) {
    // Steps of a job run back to back: a read-back follows its write before anything else.
    a.queue.push_front(std::move(job));
    return;
  }
  complete_job(a, std::move(job));
}

void EnDatService::complete_job(Axis& a, std::unique_ptr<Job> job) {
  JobResult& r = job->result;
  switch (job->kind) {
    case JobKind::Single:
      r.error = r.steps.empty() ? make_error_code(EnDatServiceErrc::stopped) : r.steps.back().error;
      break;
    case JobKind::WriteVerify: {
      for (const auto& s : r.steps) {
        if (s.error) {
          r.error = s.error;
          break;
        }
      }
      if (!r.error && r.steps.size() == 2) {
        const uint16_t written = r.steps[0].request.value;
        const uint16_t read_back = r.steps[1].reply.value();
        if (endat::check_readback(written, read_back)) {
          r.error = make_error_code(EnDatServiceErrc::write_rejected);
          char text[160];
          std::snprintf(text, sizeof(text),
                        "MRS 0x%02X parameter %u: wrote 0x%04X, read back 0x%04X "
                        "(the area is write-protected or the encoder refused the value)",
                        r.steps[0].request.mrs, r.steps[0].request.parameter, written, read_back);
          r.detail = text;
        }
      }
      break;
    }
    case JobKind::Sequence:
      for (const auto& s : r.steps) {
        if (s.error && (is_transport_error(s.error) || s.error == endat::Errc::requires_endat22)) {
          r.error = s.error;
          break;
        }
      }
      break;
  }
  if (job->cancelled) {
    ++a.counters.jobs_cancelled;
    return;
  }
  ++(r.error ? a.counters.jobs_failed : a.counters.jobs_done);
  if (job->done) job->done(r);
}

}  // namespace ds1928
