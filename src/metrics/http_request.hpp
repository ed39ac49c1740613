// The request side of the metrics endpoint's HTTP/1.x: a strict parser of the request line and
// header section, pure (bytes in, verdict out). Only what a scraper sends is accepted:
// GET or HEAD of /metrics (a query string is ignored), no body, CRLF line ends, at most
// kMaxRequestBytes of request line and headers. Everything else gets the status and a text that
// says what was wrong.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "metrics/exposition.hpp"

namespace ds1928::metrics {

inline constexpr std::size_t kMaxRequestBytes = 8192;

enum class Method : uint8_t { Get, Head };

struct HttpRequest {
  Method method = Method::Get;
  Format format = Format::Prometheus;  // by the Accept header
  bool http10 = false;                 // HTTP/1.0 (no Host required)
};

struct ParseResult {
  enum class State : uint8_t {
    Incomplete,  // more bytes may complete it: keep reading
    Complete,    // `request` is valid; `consumed` bytes end the header section
    Rejected,    // answer `status` with `reason` and close
  };
  State state = State::Incomplete;
  HttpRequest request;
  std::size_t consumed = 0;
  int status = 0;             // 400, 404, 405, 413, 431, 505 when Rejected
  std::string_view reason{};  // static text: what was wrong
};

// Parses what arrived so far (`bytes` starts at the request's first byte). Errors are reported
// as soon as the bytes show them (a malformed request line before its headers arrive), so
// garbage is answered at once instead of after the read timeout.
[[nodiscard]] ParseResult parse_request(std::string_view bytes,
                                        std::size_t limit = kMaxRequestBytes) noexcept;

// True when an Accept header value asks for OpenMetrics (a media range
// application/openmetrics-text with q > 0).
[[nodiscard]] bool accepts_openmetrics(std::string_view accept) noexcept;

[[nodiscard]] std::string_view status_text(int status) noexcept;

}  // namespace ds1928::metrics
