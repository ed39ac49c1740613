#include <algorithm>

#include "control/peer_privilege.hpp"
#include "endat_service_state.hpp"

namespace ds1928 {

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

}  // namespace ds1928
