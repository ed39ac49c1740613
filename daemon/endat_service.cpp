#include "endat_service.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>

#include "control/journal.hpp"
#include "core/module_image.hpp"
#include "endat/names.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// Errors

namespace {

class ServiceCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "endat-service"; }
  [[nodiscard]] std::string message(int c) const override {
    switch (static_cast<EnDatServiceErrc>(c)) {
      case EnDatServiceErrc::timeout:
        return "no reply from the module within the command timeout";
      case EnDatServiceErrc::not_delivered:
        return "the command did not reach the module (not executed)";
      case EnDatServiceErrc::busy:
        return "the axis' EnDat command queue is full";
      case EnDatServiceErrc::write_rejected:
        return "the value read back differs from the value written (write-protected area?)";
      case EnDatServiceErrc::cancelled:
        return "cancelled: the client went away";
      case EnDatServiceErrc::stopped:
        return "the daemon is stopping";
      case EnDatServiceErrc::no_such_axis:
        return "no such axis";
      case EnDatServiceErrc::identification_unavailable:
        return "the encoder identification could not be read";
    }
    return "unknown EnDat service error";
  }
};

}  // namespace

const std::error_category& endat_service_category() noexcept {
  static const ServiceCategory category;
  return category;
}

std::error_code make_error_code(EnDatServiceErrc e) noexcept {
  return {static_cast<int>(e), endat_service_category()};
}

std::string_view endat_error_code_name(std::error_code ec) noexcept {
  if (!ec) return "ok";
  if (ec.category() == endat_service_category()) {
    switch (static_cast<EnDatServiceErrc>(ec.value())) {
      case EnDatServiceErrc::timeout:
        return "timeout";
      case EnDatServiceErrc::not_delivered:
        return "not_delivered";
      case EnDatServiceErrc::busy:
        return "busy";
      case EnDatServiceErrc::write_rejected:
        return "write_rejected";
      case EnDatServiceErrc::cancelled:
        return "cancelled";
      case EnDatServiceErrc::stopped:
        return "stopped";
      case EnDatServiceErrc::no_such_axis:
        return "bad_argument";
      case EnDatServiceErrc::identification_unavailable:
        return "identification_unavailable";
    }
    return "internal";
  }
  if (ec.category() == endat::error_category()) {
    using endat::Errc;
    switch (static_cast<Errc>(ec.value())) {
      case Errc::truncated_reply:
      case Errc::truncated_failure_reply:
        return "truncated_reply";
      case Errc::oversized_reply:
      case Errc::oversized_failure_reply:
        return "oversized_reply";
      case Errc::command_echo_mismatch:
      case Errc::mrs_echo_mismatch:
      case Errc::block_echo_mismatch:
      case Errc::parameter_echo_mismatch:
        return "echo_mismatch";
      case Errc::requires_endat22:
        return "requires_endat22";
      case Errc::invalid_mrs:
      case Errc::unknown_command:
      case Errc::invalid_number:
      case Errc::number_out_of_range:
        return "bad_argument";
      case Errc::module_crc_failure:
        return "module_crc_error";
      case Errc::module_no_response:
        return "module_no_response";
      case Errc::module_not_supported:
        return "module_not_supported";
      case Errc::module_malformed_request:
        return "module_malformed_request";
      case Errc::module_wire_echo_mismatch:
        return "module_wire_echo_mismatch";
      case Errc::module_unknown_failure:
        return "module_failure";
      case Errc::write_not_applied:
        return "write_rejected";
      case Errc::invalid_identification:
        return "invalid_identification";
      default:
        return "internal";
    }
  }
  return "internal";
}

// ---------------------------------------------------------------------------------------------
// Identification and privilege helpers

nlohmann::json identification_json(const endat::Identification& id) {
  char hex[8];
  std::snprintf(hex, sizeof(hex), "0x%04X", id.version_word);
  nlohmann::json j{
      {"endat", id.command_set == endat::CommandSet::EnDat22 ? "2.2" : "2.1"},
      {"version_word", id.version_word},
      {"version_word_hex", hex},
      {"command_set_word", id.command_set_word},
      {"type", id.type == endat::EncoderType::Rotary ? "rotary" : "linear"},
      {"position_bits", id.position_bits},
      {"signal_periods", id.signal_periods},
      {"multiturn", id.multiturn()},
      {"revolutions", id.revolutions},
      {"steps_per_revolution", id.steps_per_revolution},
      {"id", id.id.to_string()},
      {"serial", id.serial.to_string()},
      {"warnings_supported", id.warnings_supported},
      {"checksum", id.checksum},
  };
  return j;
}

// ---------------------------------------------------------------------------------------------
// State

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

namespace {

[[nodiscard]] bool is_transport_error(std::error_code ec) noexcept {
  return ec.category() == endat_service_category();
}

}  // namespace

EnDatService::EnDatService(boost::asio::io_context& io, CycleWork& work, RegisterClient& registers,
                           const DaemonConfig& config)
    : io_(io),
      work_(work),
      registers_(registers),
      config_(config),
      poll_timer_(io),
      status_timer_(io),
      poll_period_(std::max<std::chrono::microseconds>(
          std::chrono::milliseconds(1), std::chrono::microseconds(config.cycle.period_us))),
      privileged_([group = config.socket.privileged_group](const control::PeerCredentials& p) {
        return control::peer_is_privileged(p, group);
      }) {
  for (std::size_t i = 0; i < work.axis_count(); ++i) {
    auto axis = std::make_unique<Axis>();
    if (i < config.axes.size())
      axis->timeout =
          std::chrono::milliseconds(std::max<uint32_t>(1, config.axes[i].command_timeout_ms));
    axes_.push_back(std::move(axis));
  }
}

EnDatService::~EnDatService() {
  *alive_ = false;
  stop();
}

void EnDatService::start() {
  if (running_) return;
  running_ = true;
  arm_poll();
  arm_status();
  for (std::size_t i = 0; i < axes_.size(); ++i) start_identification(i);
}

void EnDatService::stop() {
  if (!running_) return;
  running_ = false;
  poll_timer_.cancel();
  status_timer_.cancel();
  for (auto& axis : axes_) {
    std::vector<std::unique_ptr<Job>> jobs;
    if (axis->in_flight) jobs.push_back(std::move(axis->in_flight->job));
    axis->in_flight.reset();
    for (auto& j : axis->queue) jobs.push_back(std::move(j));
    axis->queue.clear();
    for (auto& j : jobs) {
      j->result.error = make_error_code(EnDatServiceErrc::stopped);
      if (!j->cancelled && j->done) j->done(j->result);
    }
  }
}

void EnDatService::set_privilege_check(std::function<bool(const control::PeerCredentials&)> check) {
  privileged_ = std::move(check);
}

bool EnDatService::may_change_encoder(const control::Request& request) const {
  return privileged_ && privileged_(request.peer());
}

const std::optional<endat::Identification>& EnDatService::identification(std::size_t axis) const {
  return axes_.at(axis)->ident;
}

EnDatService::Counters EnDatService::counters(std::size_t axis) const {
  return axes_.at(axis)->counters;
}

const EnDatService::LatencyHistogram& EnDatService::command_latency(std::size_t axis) const {
  return axes_.at(axis)->latency;
}

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

// ---------------------------------------------------------------------------------------------
// Polling the tunnel

void EnDatService::arm_poll() {
  if (!running_) return;
  poll_timer_.expires_after(poll_period_);
  poll_timer_.async_wait(
      [this, alive = std::weak_ptr<bool>(alive_)](const boost::system::error_code& ec) {
        if (ec || alive.expired()) return;
        poll();
        arm_poll();
      });
}

void EnDatService::poll() {
  const auto now = Clock::now();
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    if (!running_) return;
    poll_axis(i, now);
    dispatch(i, now);
  }
}

void EnDatService::poll_axis(std::size_t index, Clock::time_point now) {
  Axis& a = *axes_[index];
  while (auto event = work_.poll_tunnel(index)) {
    switch (event->kind) {
      case TunnelEvent::Kind::Received: {
        if (!a.in_flight || !a.in_flight->submitted) {
          if (a.awaiting_late_reply) {
            // The reply to the command that timed out: it may now be forgotten.
            ++a.counters.late_replies;
            a.awaiting_late_reply = false;
          } else {
            ++a.counters.unexpected_replies;
          }
          break;
        }
        ++a.counters.replies;
        // The deadline runs from the first submission (transmit()).
        a.latency.record(std::chrono::duration_cast<std::chrono::nanoseconds>(
                             now - (a.in_flight->deadline - a.timeout))
                             .count());
        if (a.in_flight->job->cancelled) ++a.counters.discarded_replies;
        const endat::Request& request = a.in_flight->job->steps[a.in_flight->job->next];
        if (event->full_size > event->size) {
          finish_step(index, endat::Errc::oversized_reply, {});
          break;
        }
        auto reply = endat::decode_reply(
            request, std::span<const uint8_t>(event->bytes.data(), event->size));
        if (reply)
          finish_step(index, {}, *reply);
        else
          finish_step(index, reply.error(), {});
        break;
      }
      case TunnelEvent::Kind::Sent:
        if (a.in_flight && a.in_flight->submitted && event->tag == a.in_flight->tag)
          a.in_flight->sent = true;
        break;
      case TunnelEvent::Kind::SendFailed:
      case TunnelEvent::Kind::Rejected: {
        if (!a.in_flight || !a.in_flight->submitted || event->tag != a.in_flight->tag) break;
        const auto r = event->result;
        if (event->kind == TunnelEvent::Kind::SendFailed &&
            (r == flatstream::Errc::unconfirmed || r == flatstream::Errc::timeout)) {
          // The module may hold the command and answer it: keep waiting for the reply until
          // the command's deadline. It is still the only command in flight, so a reply that
          // comes is its reply.
          a.in_flight->maybe_delivered = true;
          break;
        }
        // Certainly not executed (not_synchronised, resend_limit, channel_reset, queue_full):
        // safe to send again.
        if (a.in_flight->resends < kMaxResends && now < a.in_flight->deadline) {
          ++a.in_flight->resends;
          ++a.counters.resends;
          transmit(index, now);
        } else {
          finish_step(index, EnDatServiceErrc::not_delivered, {});
        }
        break;
      }
    }
  }
  if (a.in_flight && now >= a.in_flight->deadline && a.in_flight->deadline != Clock::time_point{}) {
    ++a.counters.timeouts;
    const bool submitted = a.in_flight->submitted;
    if (submitted && !a.in_flight->sent && !a.in_flight->maybe_delivered) {
      // Still in the master's Flatstream queue: drop it so it cannot run later.
      TunnelRequest reset;
      reset.kind = TunnelRequest::Kind::ResetChannel;
      (void)work_.submit_tunnel(index, reset);
    }
    if (submitted) {
      a.awaiting_late_reply = true;
      a.quiet_until = now + a.timeout;
    }
    finish_step(index, EnDatServiceErrc::timeout, {});
  }
}

// ---------------------------------------------------------------------------------------------
// EnDatError / EnDatWarning every second

void EnDatService::arm_status() {
  if (!running_) return;
  status_timer_.expires_after(std::chrono::seconds(1));
  status_timer_.async_wait(
      [this, alive = std::weak_ptr<bool>(alive_)](const boost::system::error_code& ec) {
        if (ec || alive.expired()) return;
        read_status_registers();
        arm_status();
      });
}

void EnDatService::read_status_registers() {
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    Axis& a = *axes_[i];
    if (a.status_pending != 0) continue;  // the previous read has not come back yet
    a.status_pending = 2;
    for (const uint16_t reg : {reg::kEnDatError, reg::kEnDatWarning}) {
      registers_.read(
          static_cast<uint16_t>(i), reg, 2,
          [this, i, reg, alive = std::weak_ptr<bool>(alive_)](std::error_code ec, uint32_t v) {
            if (alive.expired()) return;
            Axis& ax = *axes_[i];
            if (ax.status_pending > 0) --ax.status_pending;
            ax.status_error = ec;
            if (ec) return;
            const auto word = static_cast<uint16_t>(v);
            auto& counters = work_.counters(i);
            if (reg == reg::kEnDatError) {
              ax.endat_error = word;
              counters.endat_error.store(word, std::memory_order_relaxed);
            } else {
              ax.endat_warning = word;
              counters.endat_warning.store(word, std::memory_order_relaxed);
            }
          });
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Identification: ParamManuf_04..47 through the acyclic registers; else Flatstream reads

void EnDatService::refresh_identification(std::size_t index,
                                          std::function<void(std::error_code)> done) {
  if (index >= axes_.size()) {
    if (done) done(make_error_code(EnDatServiceErrc::no_such_axis));
    return;
  }
  if (done) axes_[index]->ident_waiters.push_back(std::move(done));
  start_identification(index);
}

void EnDatService::start_identification(std::size_t index) {
  Axis& a = *axes_[index];
  if (a.identifying) return;  // the running one answers every waiter
  a.identifying = true;
  a.ident_state = "reading";
  identify_by_registers(index, 0);
}

void EnDatService::identify_by_registers(std::size_t index, unsigned attempt) {
  struct Collect {
    endat::ManufacturerWords words{};
    std::error_code error;
    unsigned remaining = 0;
  };
  auto collect = std::make_shared<Collect>();
  constexpr unsigned kFirst = 4;
  collect->remaining = endat::kManufacturerWords - kFirst;
  for (unsigned w = kFirst; w < endat::kManufacturerWords; ++w) {
    registers_.read(
        static_cast<uint16_t>(index), static_cast<uint16_t>(reg::kParamManuf0 + w), 2,
        [this, index, w, attempt, collect, alive = std::weak_ptr<bool>(alive_)](std::error_code ec,
                                                                                uint32_t v) {
          if (alive.expired()) return;
          if (ec && !collect->error) collect->error = ec;
          collect->words[w] = static_cast<uint16_t>(v);
          if (--collect->remaining != 0) return;
          if (!running_)
            return identification_done(index, make_error_code(EnDatServiceErrc::stopped));
          if (collect->error) {
            spdlog::info(
                "axis {}: identification registers not readable ({}); reading over Flatstream",
                index, collect->error.message());
            return identify_by_flatstream(index);
          }
          auto ident = endat::decode_identification(collect->words);
          if (!ident) {
            // The module may still be reading the encoder after power-up: try again shortly.
            if (attempt < 4) {
              auto timer =
                  std::make_shared<boost::asio::steady_timer>(io_, std::chrono::milliseconds(250));
              timer->async_wait([this, index, attempt, timer, alive = std::weak_ptr<bool>(alive_)](
                                    const boost::system::error_code& e) {
                if (e || alive.expired() || !running_) return;
                identify_by_registers(index, attempt + 1);
              });
              return;
            }
            spdlog::info(
                "axis {}: identification registers inconsistent ({}); reading over Flatstream",
                index, ident.error().message());
            return identify_by_flatstream(index);
          }
          Axis& a = *axes_[index];
          a.words = collect->words;
          a.ident = *ident;
          a.ident_source = "registers";
          identification_done(index, {});
        });
  }
}

void EnDatService::identify_by_flatstream(std::size_t index) {
  std::vector<endat::Request> steps;
  for (unsigned w = 4; w < endat::kManufacturerWords; ++w)
    steps.push_back(
        endat::Request::read(endat::manufacturer_page_mrs(w), static_cast<uint8_t>(w % 16)));
  submit(index, JobKind::Sequence, std::move(steps), [this, index](const JobResult& r) {
    if (r.error) return identification_done(index, r.error);
    endat::ManufacturerWords words{};
    for (const auto& s : r.steps) {
      if (s.error) return identification_done(index, s.error);
      const unsigned global = (s.request.mrs - 0xA1u) / 2u * 16u + s.request.parameter;
      if (global < words.size()) words[global] = s.reply.value();
    }
    auto ident = endat::decode_identification(words);
    if (!ident) return identification_done(index, ident.error());
    Axis& a = *axes_[index];
    a.words = words;
    a.ident = *ident;
    a.ident_source = "flatstream";
    identification_done(index, {});
  });
}

void EnDatService::identification_done(std::size_t index, std::error_code error) {
  Axis& a = *axes_[index];
  a.identifying = false;
  a.ident_error = error;
  if (error) {
    a.ident_state = "failed";
    control::log_event(
        spdlog::level::warn,
        {control::LogEvent::IdentificationFailed, {}, -1, static_cast<int>(index), error.message()},
        fmt::format("axis {}: encoder identification failed: {}", index, error.message()));
  } else {
    a.ident_state = "ok";
    spdlog::info("axis {}: EnDat {} {} encoder, {} position bits, ID {}, serial {} (from {})",
                 index, a.ident->command_set == endat::CommandSet::EnDat22 ? "2.2" : "2.1",
                 a.ident->type == endat::EncoderType::Rotary ? "rotary" : "linear",
                 a.ident->position_bits, a.ident->id.to_string(), a.ident->serial.to_string(),
                 a.ident_source);
  }
  if (identified_hook_) identified_hook_(index, error, error ? nullptr : &*a.ident);
  auto waiters = std::move(a.ident_waiters);
  a.ident_waiters.clear();
  for (auto& w : waiters) w(error);
}

bool EnDatService::identifying(std::size_t axis) const {
  return axes_.at(axis)->identifying;
}

nlohmann::json EnDatService::identification_reply(std::size_t axis) const {
  const Axis& a = *axes_.at(axis);
  nlohmann::json j{{"axis", axis}, {"source", a.ident_source}};
  if (a.ident) j["identification"] = identification_json(*a.ident);
  nlohmann::json words = nlohmann::json::object();
  for (unsigned w = 4; w < endat::kManufacturerWords; ++w) {
    char hex[8];
    std::snprintf(hex, sizeof(hex), "0x%04X", a.words[w]);
    nlohmann::json word{{"value", a.words[w]}, {"value_hex", hex}};
    if (const auto name = endat::manufacturer_word_name(w); !name.empty())
      word["name"] = std::string(name);
    words[std::to_string(w)] = std::move(word);
  }
  j["words"] = std::move(words);
  if (a.endat_error) {
    j["endat_error"] = *a.endat_error;
    j["endat_error_names"] = endat::endat_error_names(*a.endat_error);
  }
  if (a.endat_warning) {
    j["endat_warning"] = *a.endat_warning;
    j["endat_warning_names"] = endat::endat_warning_names(*a.endat_warning);
  }
  return j;
}

// ---------------------------------------------------------------------------------------------
// Status

nlohmann::json EnDatService::status_json(std::size_t index) const {
  if (index >= axes_.size()) return nullptr;
  const Axis& a = *axes_[index];
  nlohmann::json id{{"state", a.ident_state}};
  if (!a.ident_source.empty()) id["source"] = a.ident_source;
  if (a.ident_error)
    id["error"] = {{"code", std::string(endat_error_code_name(a.ident_error))},
                   {"message", a.ident_error.message()}};
  if (a.ident) id.update(identification_json(*a.ident));
  nlohmann::json j{{"identification", id}};
  if (a.endat_error) {
    j["endat_error"] = *a.endat_error;
    j["endat_error_names"] = endat::endat_error_names(*a.endat_error);
  }
  if (a.endat_warning) {
    j["endat_warning"] = *a.endat_warning;
    j["endat_warning_names"] = endat::endat_warning_names(*a.endat_warning);
  }
  if (a.status_error) j["status_read_error"] = a.status_error.message();
  const Counters& c = a.counters;
  j["commands"] = {{"queued", a.queue.size()},
                   {"in_flight", a.in_flight.has_value()},
                   {"awaiting_late_reply", a.awaiting_late_reply},
                   {"sent", c.commands_sent},
                   {"replies", c.replies},
                   {"timeouts", c.timeouts},
                   {"resends", c.resends},
                   {"late_replies", c.late_replies},
                   {"unexpected_replies", c.unexpected_replies},
                   {"done", c.jobs_done},
                   {"failed", c.jobs_failed},
                   {"cancelled", c.jobs_cancelled}};
  return j;
}

}  // namespace ds1928
