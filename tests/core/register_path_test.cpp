// The register path (core/register_path.hpp): the one way a register request goes from the
// services to a bus. Queue limits with their precise error, order, exactly one result per
// request, a target that waits, results held while nobody polls, and a request whose result
// comes after its caller gave up (RegisterClient's timeout drops it by its tag).
#include "core/register_path.hpp"

#include <catch2/catch.hpp>
#include <deque>
#include <vector>

using namespace ds1928;

namespace {

// A bus that answers reads with the register number + 1, refuses axis 9 at once, takes at most
// `room` requests before it waits, and completes the taken ones when told (like an SDO transfer
// that ends in a later cycle).
class FakeTarget final : public RegisterTarget {
 public:
  explicit FakeTarget(RegisterPath& path) : path_(path) {}
  Offer offer(const RegisterRequest& r) noexcept override {
    ++offers;
    if (r.axis == 9) {
      (void)path_.complete({r.tag, std::make_error_code(std::errc::no_such_device), 0});
      return Offer::kTaken;
    }
    if (in_flight.size() >= room) return Offer::kWait;
    in_flight.push_back(r);
    return Offer::kTaken;
  }
  // Cycle thread: the transfers in flight end (as many as results have room for).
  void finish() {
    while (!in_flight.empty() && path_.flush()) {
      const RegisterRequest r = in_flight.front();
      in_flight.pop_front();
      (void)path_.complete({r.tag, {}, r.write ? 0u : r.reg + 1u});
    }
  }
  std::size_t room = 1000;
  std::size_t offers = 0;
  std::deque<RegisterRequest> in_flight;

 private:
  RegisterPath& path_;
};

RegisterRequest read(uint32_t tag, uint16_t axis = 0) {
  return {tag, axis, static_cast<uint16_t>(100 + tag), 2, false, 0};
}

}  // namespace

TEST_CASE("Register path: a full queue refuses with a precise error and keeps what it holds",
          "[core][register_path]") {
  RegisterPath path;
  for (uint32_t t = 1; t <= kRegisterQueueDepth; ++t) REQUIRE_FALSE(path.submit(read(t)));
  const std::error_code full = path.submit(read(999));
  REQUIRE(full == RegisterPathError::kQueueFull);
  CHECK_THAT(full.message(), Catch::Contains("register request queue full") &&
                                 Catch::Contains(std::to_string(kRegisterQueueDepth)));
  CHECK(std::string(full.category().name()) == "register_path");
  // The refused request was not queued: serving yields exactly the first kRegisterQueueDepth.
  FakeTarget bus(path);
  CHECK(path.serve(bus) == kRegisterQueueDepth);
  bus.finish();
  std::vector<uint32_t> tags;
  RegisterResult r;
  while (path.poll(r)) tags.push_back(r.tag);
  REQUIRE(tags.size() == kRegisterQueueDepth);
  CHECK(tags.front() == 1);
  CHECK(tags.back() == kRegisterQueueDepth);
  CHECK_FALSE(path.submit(read(1000)));  // room again
}

TEST_CASE("Register path: requests are offered in order, one result each",
          "[core][register_path]") {
  RegisterPath path;
  FakeTarget bus(path);
  REQUIRE_FALSE(path.submit(read(1)));
  REQUIRE_FALSE(path.submit(read(2, 9)));  // answered at once with an error
  REQUIRE_FALSE(path.submit(read(3)));
  CHECK(path.serve(bus) == 3);
  CHECK(path.requests_empty());
  bus.finish();
  std::vector<RegisterResult> results;
  RegisterResult r;
  while (path.poll(r)) results.push_back(r);
  REQUIRE(results.size() == 3);
  CHECK(results[0].tag == 2);  // the immediate refusal comes first
  CHECK(results[0].error == std::errc::no_such_device);
  CHECK((results[1].tag == 1 && !results[1].error && results[1].value == 102));
  CHECK((results[2].tag == 3 && !results[2].error && results[2].value == 104));
  CHECK(path.serve(bus) == 0);  // nothing queued, nothing offered twice
  CHECK_FALSE(path.poll(r));
}

TEST_CASE("Register path: a target that waits keeps the request first in line",
          "[core][register_path]") {
  RegisterPath path;
  FakeTarget bus(path);
  bus.room = 1;
  for (uint32_t t = 1; t <= 3; ++t) REQUIRE_FALSE(path.submit(read(t)));
  CHECK(path.serve(bus) == 1);  // request 2 waits, 3 is behind it
  CHECK_FALSE(path.requests_empty());
  CHECK(path.serve(bus, 1) == 0);
  bus.finish();
  CHECK(path.serve(bus, 1) == 1);  // max: one per call (CAN-I/O takes one job at a time)
  REQUIRE(bus.in_flight.size() == 1);
  CHECK(bus.in_flight.front().tag == 2);
  bus.finish();
  CHECK(path.serve(bus) == 1);
  bus.finish();
  std::vector<uint32_t> tags;
  RegisterResult r;
  while (path.poll(r)) tags.push_back(r.tag);
  CHECK(tags == std::vector<uint32_t>{1, 2, 3});
}

TEST_CASE("Register path: while nobody polls, one result is held and nothing more is offered",
          "[core][register_path]") {
  RegisterPath path;
  FakeTarget bus(path);
  uint32_t tag = 0;
  // Fill the results: kRegisterQueueDepth answered requests nobody polls.
  for (std::size_t i = 0; i < kRegisterQueueDepth; ++i) REQUIRE_FALSE(path.submit(read(++tag)));
  CHECK(path.serve(bus) == kRegisterQueueDepth);
  bus.finish();
  CHECK(path.can_complete());
  // The next one's result finds no room: held, and the path offers nothing while it is.
  for (int i = 0; i < 3; ++i) REQUIRE_FALSE(path.submit(read(++tag)));
  CHECK(path.serve(bus, 1) == 1);
  bus.finish();
  CHECK_FALSE(path.can_complete());
  CHECK_FALSE(path.complete({777, {}, 0}));  // a second result is refused, not overwriting
  const std::size_t offers = bus.offers;
  CHECK(path.serve(bus) == 0);
  CHECK(bus.offers == offers);
  // Polled: every result in order, the held one included, none lost, none twice.
  std::vector<uint32_t> tags;
  RegisterResult r;
  while (path.poll(r)) tags.push_back(r.tag);
  CHECK(path.flush());
  while (path.poll(r)) tags.push_back(r.tag);
  CHECK(path.serve(bus) == 2);
  bus.finish();
  while (path.poll(r)) tags.push_back(r.tag);
  REQUIRE(tags.size() == tag);
  for (uint32_t i = 0; i < tag; ++i) CHECK(tags[i] == i + 1);
}

TEST_CASE("Register path: a result after its caller gave up carries its own tag",
          "[core][register_path]") {
  // The caller (RegisterClient) answers errc::timed_out itself and forgets the tag; the late
  // result must still come, once, under that tag, so it can be dropped and not be taken for the
  // answer of a later request.
  RegisterPath path;
  FakeTarget bus(path);
  REQUIRE_FALSE(path.submit(read(41)));
  CHECK(path.serve(bus) == 1);
  REQUIRE_FALSE(path.submit(read(42)));  // the caller's next request, after its timeout
  CHECK(path.serve(bus) == 1);
  bus.finish();
  RegisterResult r;
  REQUIRE(path.poll(r));
  CHECK(r.tag == 41);
  REQUIRE(path.poll(r));
  CHECK(r.tag == 42);
  CHECK(r.value == 143);  // its own answer (register 142 + 1), not the earlier one's
  CHECK_FALSE(path.poll(r));
}
