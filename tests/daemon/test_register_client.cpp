// RegisterClient over the register path: every caller hears exactly once — the bus' answer, or
// errc::timed_out when the bus does not answer in time; a result that comes after the timeout is
// dropped by its tag and never taken for a later request's answer.
#include <boost/asio/io_context.hpp>
#include <catch2/catch.hpp>
#include <deque>
#include <optional>

#include "core/bus.hpp"
#include "register_client.hpp"

using namespace ds1928;

namespace {

// A bus whose cycle is stepped by the test: it takes every request and answers only when told.
class SteppedBus final : public BusDriver, private RegisterTarget {
 public:
  [[nodiscard]] std::string_view name() const noexcept override { return "stepped"; }
  [[nodiscard]] std::error_code start() override { return {}; }
  void stop() noexcept override {}
  ExchangeResult exchange(std::span<AxisIo>, int64_t, uint64_t) noexcept override {
    registers().serve(*this);
    return {};
  }
  [[nodiscard]] BusState state() const noexcept override { return BusState::Operational; }
  // Cycle side: the oldest taken request is answered (its register number as the value).
  void answer_one() {
    if (taken_.empty()) return;
    const RegisterRequest r = taken_.front();
    taken_.pop_front();
    (void)registers().complete({r.tag, {}, r.reg});
  }
  [[nodiscard]] std::size_t taken() const noexcept { return taken_.size(); }

 private:
  Offer offer(const RegisterRequest& r) noexcept override {
    taken_.push_back(r);
    return Offer::kTaken;
  }
  std::deque<RegisterRequest> taken_;
};

}  // namespace

TEST_CASE(
    "RegisterClient: a request the bus does not answer in time times out once, its late "
    "result is dropped",
    "[daemon][register_path]") {
  boost::asio::io_context io;
  SteppedBus bus;
  RegisterClient client(io, bus, std::chrono::milliseconds(20));
  client.start(std::chrono::microseconds(500));
  int first_calls = 0;
  std::error_code first_error;
  client.read(0, 1234, 2, [&](std::error_code ec, uint32_t) {
    ++first_calls;
    first_error = ec;
  });
  bus.exchange({}, 0, 0);  // the bus takes it and does not answer
  REQUIRE(bus.taken() == 1);
  // Until the caller's deadline has passed (the client's own clock) and it said so.
  for (int i = 0; i < 2000 && first_calls == 0; ++i) io.run_for(std::chrono::milliseconds(1));
  REQUIRE(first_calls == 1);
  CHECK(first_error == std::errc::timed_out);
  CHECK(client.pending() == 0);
  // The next request is answered; the late answer of the first comes before it.
  std::optional<uint32_t> second;
  client.read(0, 77, 2, [&](std::error_code ec, uint32_t v) {
    CHECK_FALSE(ec);
    second = v;
  });
  bus.exchange({}, 0, 0);
  bus.answer_one();  // the first request's, late
  bus.answer_one();  // the second's
  for (int i = 0; i < 2000 && !second; ++i) io.run_for(std::chrono::milliseconds(1));
  REQUIRE(second.has_value());
  CHECK(*second == 77);  // its own answer, not the late one (1234)
  CHECK(first_calls == 1);
  CHECK(client.pending() == 0);
  client.stop();
}
