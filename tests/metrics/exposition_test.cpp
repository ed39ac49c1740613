// The exposition writer's exact text in both formats, and the metrics.listen address syntax.
#include "metrics/exposition.hpp"

#include <catch2/catch.hpp>
#include <string>

#include "config/config_metrics.hpp"

using namespace ds1928;
using namespace ds1928::metrics;

namespace {

std::string render(Format f) {
  Exposition out(f);
  out.family("ds1928_build", Type::Info, "Version.");
  out.sample({{"version", "1.2.3"}}, uint64_t{1});
  out.family("ds1928_cycles", Type::Counter, "Cycles run.");
  out.sample(uint64_t{42});
  out.family("ds1928_cycle_period_seconds", Type::Gauge, "Period\\with \"quotes\"\nand a line.",
             "seconds");
  out.sample({{"axis", "0"}, {"name", "a\"b\\c\nd"}}, 0.001);
  out.family("ds1928_latency_seconds", Type::Histogram, "Latency.", "seconds");
  const double upper[] = {0.001, 0.5};
  const uint64_t counts[] = {3, 0, 2};
  out.histogram({{"node", "1"}}, upper, counts, 2.25);
  return out.finish();
}

}  // namespace

TEST_CASE("Prometheus text format 0.0.4, exactly", "[metrics][exposition]") {
  CHECK(render(Format::Prometheus) ==
        "# HELP ds1928_build_info Version.\n"
        "# TYPE ds1928_build_info gauge\n"
        "ds1928_build_info{version=\"1.2.3\"} 1\n"
        "# HELP ds1928_cycles_total Cycles run.\n"
        "# TYPE ds1928_cycles_total counter\n"
        "ds1928_cycles_total 42\n"
        "# HELP ds1928_cycle_period_seconds Period\\\\with \"quotes\"\\nand a line.\n"
        "# TYPE ds1928_cycle_period_seconds gauge\n"
        "ds1928_cycle_period_seconds{axis=\"0\",name=\"a\\\"b\\\\c\\nd\"} 0.001\n"
        "# HELP ds1928_latency_seconds Latency.\n"
        "# TYPE ds1928_latency_seconds histogram\n"
        "ds1928_latency_seconds_bucket{node=\"1\",le=\"0.001\"} 3\n"
        "ds1928_latency_seconds_bucket{node=\"1\",le=\"0.5\"} 3\n"
        "ds1928_latency_seconds_bucket{node=\"1\",le=\"+Inf\"} 5\n"
        "ds1928_latency_seconds_count{node=\"1\"} 5\n"
        "ds1928_latency_seconds_sum{node=\"1\"} 2.25\n");
}

TEST_CASE("OpenMetrics 1.0.0, exactly", "[metrics][exposition]") {
  CHECK(render(Format::OpenMetrics) ==
        "# HELP ds1928_build Version.\n"
        "# TYPE ds1928_build info\n"
        "ds1928_build_info{version=\"1.2.3\"} 1\n"
        "# HELP ds1928_cycles Cycles run.\n"
        "# TYPE ds1928_cycles counter\n"
        "ds1928_cycles_total 42\n"
        "# HELP ds1928_cycle_period_seconds Period\\\\with \\\"quotes\\\"\\nand a line.\n"
        "# TYPE ds1928_cycle_period_seconds gauge\n"
        "# UNIT ds1928_cycle_period_seconds seconds\n"
        "ds1928_cycle_period_seconds{axis=\"0\",name=\"a\\\"b\\\\c\\nd\"} 0.001\n"
        "# HELP ds1928_latency_seconds Latency.\n"
        "# TYPE ds1928_latency_seconds histogram\n"
        "# UNIT ds1928_latency_seconds seconds\n"
        "ds1928_latency_seconds_bucket{node=\"1\",le=\"0.001\"} 3\n"
        "ds1928_latency_seconds_bucket{node=\"1\",le=\"0.5\"} 3\n"
        "ds1928_latency_seconds_bucket{node=\"1\",le=\"+Inf\"} 5\n"
        "ds1928_latency_seconds_count{node=\"1\"} 5\n"
        "ds1928_latency_seconds_sum{node=\"1\"} 2.25\n"
        "# EOF\n");
  CHECK(content_type(Format::OpenMetrics) ==
        "application/openmetrics-text; version=1.0.0; charset=utf-8");
  CHECK(content_type(Format::Prometheus) == "text/plain; version=0.0.4; charset=utf-8");
}

TEST_CASE("metrics.listen takes IPv4 or bracketed IPv6 with a port", "[metrics][config]") {
  const auto v4 = parse_listen_address("127.0.0.1:9928");
  REQUIRE(v4);
  CHECK(v4->address == "127.0.0.1");
  CHECK(v4->port == 9928);
  const auto v6 = parse_listen_address("[::1]:0");
  REQUIRE(v6);
  CHECK(v6->address == "::1");
  CHECK(v6->port == 0);
  for (const char* bad :
       {"", "9928", ":9928", "127.0.0.1", "127.0.0.1:", "127.0.0.1:65536", "127.0.0.1:99x",
        "localhost:9928", "::1:9928", "[::1]", "[::1]:", "1.2.3:80", "127.0.0.1:-1"}) {
    INFO(bad);
    CHECK_FALSE(parse_listen_address(bad));
  }
}
