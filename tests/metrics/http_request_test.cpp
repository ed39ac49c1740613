// The metrics endpoint's request parser, byte by byte: what a scraper sends is accepted, with the
// format its Accept header asks for; everything else is refused with the status that says why,
// as early as the bytes show it.
#include "metrics/http_request.hpp"

#include <catch2/catch.hpp>
#include <string>

using namespace ds1928::metrics;
using State = ParseResult::State;

namespace {

ParseResult parse(const std::string& bytes) {
  return parse_request(bytes);
}

void check_rejected(const std::string& bytes, int status, std::string_view reason_part) {
  INFO(bytes);
  const ParseResult r = parse(bytes);
  REQUIRE(r.state == State::Rejected);
  CHECK(r.status == status);
  CHECK_THAT(std::string(r.reason), Catch::Contains(std::string(reason_part)));
}

}  // namespace

TEST_CASE("A Prometheus scrape is accepted with the format it asks for", "[metrics][http]") {
  const std::string prometheus =
      "GET /metrics HTTP/1.1\r\n"
      "Host: 127.0.0.1:9928\r\n"
      "User-Agent: Prometheus/2.42.0\r\n"
      "Accept: application/openmetrics-text;version=1.0.0,application/openmetrics-text;"
      "version=0.0.1;q=0.75,text/plain;version=0.0.4;q=0.5,*/*;q=0.1\r\n"
      "Accept-Encoding: gzip\r\n"
      "X-Prometheus-Scrape-Timeout-Seconds: 10\r\n"
      "\r\n";
  const ParseResult r = parse(prometheus);
  REQUIRE(r.state == State::Complete);
  CHECK(r.consumed == prometheus.size());
  CHECK(r.request.method == Method::Get);
  CHECK(r.request.format == Format::OpenMetrics);

  const ParseResult curl = parse("GET /metrics HTTP/1.1\r\nHost: localhost\r\nAccept: */*\r\n\r\n");
  REQUIRE(curl.state == State::Complete);
  CHECK(curl.request.format == Format::Prometheus);

  const ParseResult head = parse("HEAD /metrics?x=1 HTTP/1.0\r\n\r\n");  // 1.0: no Host needed
  REQUIRE(head.state == State::Complete);
  CHECK(head.request.method == Method::Head);
  CHECK(head.request.http10);
}

TEST_CASE("A request arriving in pieces is complete only at the empty line", "[metrics][http]") {
  const std::string full = "GET /metrics HTTP/1.1\r\nHost: h\r\n\r\n";
  for (std::size_t n = 0; n < full.size(); ++n) {
    INFO(n);
    CHECK(parse(full.substr(0, n)).state == State::Incomplete);
  }
  CHECK(parse(full).state == State::Complete);
  // Bytes after the header section (a pipelined request) are not part of this one.
  const ParseResult r = parse(full + "GET /");
  REQUIRE(r.state == State::Complete);
  CHECK(r.consumed == full.size());
}

TEST_CASE("Accept: OpenMetrics only when a range names it with q > 0", "[metrics][http]") {
  CHECK(accepts_openmetrics("application/openmetrics-text"));
  CHECK(accepts_openmetrics("text/plain, Application/OpenMetrics-Text; version=1.0.0"));
  CHECK(accepts_openmetrics("application/openmetrics-text;q=0.5"));
  CHECK_FALSE(accepts_openmetrics("application/openmetrics-text;q=0"));
  CHECK_FALSE(accepts_openmetrics("application/openmetrics-text; q=0.000"));
  CHECK_FALSE(accepts_openmetrics("text/plain;version=0.0.4"));
  CHECK_FALSE(accepts_openmetrics("*/*"));
  CHECK_FALSE(accepts_openmetrics(""));
}

TEST_CASE("Wrong method, resource or version get 405, 404, 505", "[metrics][http]") {
  check_rejected("POST /metrics HTTP/1.1\r\nHost: h\r\n\r\n", 405, "only GET and HEAD");
  check_rejected("DELETE / HTTP/1.1\r\n", 405, "only GET and HEAD");
  check_rejected("GET / HTTP/1.1\r\n", 404, "/metrics");
  check_rejected("GET /metricsx HTTP/1.1\r\n", 404, "/metrics");
  check_rejected("GET /metrics/ HTTP/1.1\r\n", 404, "/metrics");
  check_rejected("GET /metrics HTTP/2.0\r\n", 505, "HTTP/1.0 and HTTP/1.1");
  // The status is known from the request line: no need to wait for the headers.
  CHECK(parse("GET /favicon.ico HTTP/1.1\r\n").status == 404);
}

TEST_CASE("Malformed requests get 400 naming the fault, as soon as it shows", "[metrics][http]") {
  check_rejected(std::string("\x16\x03\x01\x02\x00", 5), 400, "method is not a token");  // TLS
  check_rejected("\x01", 400, "method is not a token");
  check_rejected(" GET", 400, "starts with a space");
  check_rejected("GET  /metrics HTTP/1.1\r\n", 400, "expected 'METHOD /metrics HTTP/1.1'");
  check_rejected("GET /metrics HTTP/1.1 x\r\n", 400, "expected 'METHOD /metrics HTTP/1.1'");
  check_rejected("GET /metrics\r\n", 400, "expected 'METHOD /metrics HTTP/1.1'");
  check_rejected("GET /metrics FTP/1.1\r\n", 400, "version");
  check_rejected("GET metrics HTTP/1.1\r\n", 400, "absolute path");
  check_rejected("GET /met\x7frics HTTP/1.1\r\n", 400, "control or non-ASCII");
  check_rejected("GET /metrics HTTP/1.1\n", 400, "CRLF");
  check_rejected("GET /metrics HTTP/1.1\r\nHost: h\n\n", 400, "CRLF");
  check_rejected("GET /metrics HTTP/1.1\r\nHost: h\rX", 400, "CRLF");
  check_rejected("GET /metrics HTTP/1.1\r\nHost: h\r\n folded\r\n\r\n", 400, "folding");
  check_rejected("GET /metrics HTTP/1.1\r\nNoColon\r\n\r\n", 400, "'Name: value'");
  check_rejected("GET /metrics HTTP/1.1\r\n: empty\r\n\r\n", 400, "'Name: value'");
  check_rejected("GET /metrics HTTP/1.1\r\nBad Name: v\r\n\r\n", 400, "not a token");
  check_rejected(std::string("GET /metrics HTTP/1.1\r\nX: a") + '\0' + "b\r\n\r\n", 400,
                 "control byte");
  check_rejected("GET /metrics HTTP/1.1\r\nHost: a\r\nHost: b\r\n\r\n", 400, "more than one Host");
  check_rejected("GET /metrics HTTP/1.1\r\n\r\n", 400, "without a Host");
}

TEST_CASE("A body is refused with 413", "[metrics][http]") {
  check_rejected("GET /metrics HTTP/1.1\r\nHost: h\r\nContent-Length: 5\r\n\r\nhello", 413, "body");
  check_rejected("GET /metrics HTTP/1.1\r\nHost: h\r\nTransfer-Encoding: chunked\r\n\r\n", 413,
                 "body");
  CHECK(parse("GET /metrics HTTP/1.1\r\nHost: h\r\nContent-Length: 0\r\n\r\n").state ==
        State::Complete);
}

TEST_CASE("More than 8 KiB of request line or headers is refused with 431", "[metrics][http]") {
  // A header section that would end exactly at the limit is accepted; one byte more is not.
  const std::string head = "GET /metrics HTTP/1.1\r\nHost: h\r\nX: ";
  const std::string tail = "\r\n\r\n";
  const std::string fits =
      head + std::string(kMaxRequestBytes - head.size() - tail.size(), 'a') + tail;
  REQUIRE(fits.size() == kMaxRequestBytes);
  CHECK(parse(fits).state == State::Complete);
  const std::string over =
      head + std::string(kMaxRequestBytes - head.size() - tail.size() + 1, 'a') + tail;
  check_rejected(over, 431, "8 KiB");
  // The buffer is full without the empty line: refused, not waited for.
  check_rejected(head + std::string(kMaxRequestBytes - head.size(), 'a'), 431, "8 KiB");
  check_rejected("GET /" + std::string(kMaxRequestBytes, 'a'), 431, "request line");
}

TEST_CASE("Status texts", "[metrics][http]") {
  CHECK(status_text(200) == "OK");
  CHECK(status_text(413) == "Content Too Large");
  CHECK(status_text(431) == "Request Header Fields Too Large");
}
