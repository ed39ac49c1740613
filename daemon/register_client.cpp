#include "register_client.hpp"

namespace ds1928 {

RegisterClient::RegisterClient(boost::asio::io_context& io, BusDriver& bus,
                               std::chrono::milliseconds timeout)
    : io_(io), bus_(bus), timeout_(timeout), timer_(io) {}

RegisterClient::~RegisterClient() {
  stop();
}

void RegisterClient::read(uint16_t axis, uint16_t reg, uint8_t size, Callback done) {
  submit(RegisterRequest{0, axis, reg, size, false, 0}, std::move(done));
}

void RegisterClient::write(uint16_t axis, uint16_t reg, uint8_t size, uint32_t value,
                           Callback done) {
  submit(RegisterRequest{0, axis, reg, size, true, value}, std::move(done));
}

void RegisterClient::submit(const RegisterRequest& request, Callback done) {
  RegisterRequest r = request;
  r.tag = next_tag_++;
  if (next_tag_ == 0) next_tag_ = 1;
  if (!backlog_.empty() || !bus_.submit(r)) {
    backlog_.emplace_back(r, std::move(done));
    return;
  }
  in_flight_.emplace(r.tag, Pending{std::move(done), std::chrono::steady_clock::now() + timeout_});
}

void RegisterClient::start(std::chrono::microseconds period) {
  period_ = period;
  running_ = true;
  arm();
}

void RegisterClient::stop() {
  running_ = false;
  timer_.cancel();
}

void RegisterClient::arm() {
  if (!running_) return;
  timer_.expires_after(period_);
  timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) return;
    poll();
    arm();
  });
}

void RegisterClient::poll() {
  RegisterResult result;
  while (bus_.poll(result)) {
    auto it = in_flight_.find(result.tag);
    if (it == in_flight_.end()) continue;  // timed out earlier: already answered
    auto done = std::move(it->second.done);
    in_flight_.erase(it);
    done(result.error, result.value);
  }
  while (!backlog_.empty()) {
    auto& [request, done] = backlog_.front();
    if (!bus_.submit(request)) break;
    in_flight_.emplace(request.tag,
                       Pending{std::move(done), std::chrono::steady_clock::now() + timeout_});
    backlog_.pop_front();
  }
  const auto now = std::chrono::steady_clock::now();
  for (auto it = in_flight_.begin(); it != in_flight_.end();) {
    if (it->second.deadline <= now) {
      auto done = std::move(it->second.done);
      it = in_flight_.erase(it);
      done(std::make_error_code(std::errc::timed_out), 0);
    } else {
      ++it;
    }
  }
}

}  // namespace ds1928
