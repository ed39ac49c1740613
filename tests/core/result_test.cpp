// Result<T>: the one expected-like type every layer returns. An error-code enum of any layer
// converts through its own make_error_code; a value and an error never stand together.
#include "core/result.hpp"

#include <catch2/catch.hpp>
#include <string>
#include <system_error>

#include "core/clock.hpp"

namespace probe {

enum class ProbeError : int { kBroken = 1 };

const std::error_category& probe_category() noexcept {
  static const struct : std::error_category {
    const char* name() const noexcept override { return "probe"; }
    std::string message(int) const override { return "broken"; }
  } category;
  return category;
}

std::error_code make_error_code(ProbeError e) noexcept {
  return {static_cast<int>(e), probe_category()};
}

}  // namespace probe

template <>
struct std::is_error_code_enum<probe::ProbeError> : std::true_type {};

using ds1928::Result;

TEST_CASE("a Result holds a value and no error", "[core][result]") {
  Result<std::string> r = std::string("value");
  REQUIRE(r);
  CHECK(r.has_value());
  CHECK(r.value() == "value");
  CHECK(*r == "value");
  CHECK(r->size() == 5);
  CHECK_FALSE(r.error());
  r.value() += "!";
  CHECK(*r == "value!");
}

TEST_CASE("a Result holds an error of any layer's category and no value", "[core][result]") {
  const Result<int> from_enum = probe::ProbeError::kBroken;  // through ADL's make_error_code
  CHECK_FALSE(from_enum);
  CHECK_FALSE(from_enum.has_value());
  CHECK(from_enum.error() == probe::ProbeError::kBroken);
  CHECK(from_enum.error().category().name() == std::string("probe"));

  const Result<int> from_code = std::make_error_code(std::errc::timed_out);
  CHECK_FALSE(from_code);
  CHECK(from_code.error() == std::errc::timed_out);
}

TEST_CASE("steady_clock reads the same CLOCK_MONOTONIC as rt::now_ns", "[core][clock]") {
  // The non-RT services' chrono deadlines and the ns stamps of the buses must be one clock.
  using std::chrono::duration_cast;
  using std::chrono::nanoseconds;
  using std::chrono::steady_clock;
  const int64_t before = ds1928::rt::now_ns();
  const int64_t chrono_ns =
      duration_cast<nanoseconds>(steady_clock::now().time_since_epoch()).count();
  const int64_t after = ds1928::rt::now_ns();
  CHECK(before <= chrono_ns);
  CHECK(chrono_ns <= after);
  // realtime_ns is the wall clock: after 2020 and not the monotonic one.
  CHECK(ds1928::rt::realtime_ns() > int64_t{1'577'836'800} * ds1928::rt::kNsPerSec);
}
