// Acyclic module-register access for the normal thread: submits RegisterRequests to the bus
// driver and hands each result to the callback that asked for it. Polled from a timer on the
// daemon's io_context (the driver completes requests between cycles).
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <system_error>

#include "core/bus.hpp"

namespace ds1928 {

class RegisterClient {
 public:
  using Callback = std::function<void(std::error_code, uint32_t value)>;

  RegisterClient(boost::asio::io_context& io, BusDriver& bus,
                 std::chrono::milliseconds timeout = std::chrono::milliseconds(2000));
  ~RegisterClient();

  // Queues a read/write; the callback runs on the io_context's thread exactly once: with the
  // driver's result, or errc::timed_out.
  void read(uint16_t axis, uint16_t reg, uint8_t size, Callback done);
  void write(uint16_t axis, uint16_t reg, uint8_t size, uint32_t value, Callback done);

  // Starts the polling timer (every `period`).
  void start(std::chrono::microseconds period);
  void stop();

  // Requests submitted and not yet answered.
  [[nodiscard]] std::size_t pending() const noexcept { return in_flight_.size() + backlog_.size(); }

 private:
  struct Pending {
    Callback done;
    std::chrono::steady_clock::time_point deadline;
  };
  void submit(const RegisterRequest& r, Callback done);
  void poll();
  void arm();

  boost::asio::io_context& io_;
  BusDriver& bus_;
  std::chrono::milliseconds timeout_;
  std::chrono::microseconds period_{1000};
  boost::asio::steady_timer timer_;
  bool running_ = false;
  uint32_t next_tag_ = 1;
  std::map<uint32_t, Pending> in_flight_;
  std::deque<std::pair<RegisterRequest, Callback>> backlog_;  // driver queue was full
};

}  // namespace ds1928
