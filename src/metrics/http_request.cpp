#include "metrics/http_request.hpp"

#include <algorithm>
#include <charconv>

namespace ds1928::metrics {
namespace {

using State = ParseResult::State;

// RFC 9110 tchar.
bool is_tchar(char c) noexcept {
  if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9')) return true;
  return std::string_view("!#$%&'*+-.^_`|~").find(c) != std::string_view::npos;
}

bool is_vchar_or_ws(char c) noexcept {
  const auto u = static_cast<unsigned char>(c);
  return c == ' ' || c == '\t' || (u >= 0x21 && u != 0x7F);  // obs-text (≥ 0x80) allowed
}

bool iequals(std::string_view a, std::string_view b) noexcept {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           const auto lower = [](char c) { return c >= 'A' && c <= 'Z' ? char(c - 'A' + 'a') : c; };
           return lower(x) == lower(y);
         });
}

std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

ParseResult reject(int status, std::string_view reason) noexcept {
  ParseResult r;
  r.state = State::Rejected;
  r.status = status;
  r.reason = reason;
  return r;
}

// Checks as much of the request line as has arrived: a bad first byte is rejected without
// waiting for the line end.
ParseResult check_partial_line(std::string_view bytes) noexcept {
  for (char c : bytes) {
    if (c == ' ') break;
    if (!is_tchar(c)) return reject(400, "malformed request line: the method is not a token");
  }
  if (!bytes.empty() && bytes.front() == ' ')
    return reject(400, "malformed request line: it starts with a space");
  return {};
}

ParseResult parse_request_line(std::string_view line, HttpRequest& req) noexcept {
  // method SP request-target SP HTTP-version, nothing else (no extra spaces).
  const auto sp1 = line.find(' ');
  if (sp1 == std::string_view::npos || sp1 == 0)
    return reject(400, "malformed request line: expected 'METHOD /metrics HTTP/1.1'");
  const auto sp2 = line.find(' ', sp1 + 1);
  if (sp2 == std::string_view::npos || sp2 == sp1 + 1 ||
      line.find(' ', sp2 + 1) != std::string_view::npos)
    return reject(400, "malformed request line: expected 'METHOD /metrics HTTP/1.1'");
  const std::string_view method = line.substr(0, sp1);
  const std::string_view target = line.substr(sp1 + 1, sp2 - sp1 - 1);
  const std::string_view version = line.substr(sp2 + 1);
  for (char c : method)
    if (!is_tchar(c)) return reject(400, "malformed request line: the method is not a token");
  for (char c : target) {
    const auto u = static_cast<unsigned char>(c);
    if (u <= 0x20 || u >= 0x7F)
      return reject(400, "malformed request line: control or non-ASCII byte in the target");
  }
  if (version == "HTTP/1.1")
    req.http10 = false;
  else if (version == "HTTP/1.0")
    req.http10 = true;
  else if (version.size() == 8 && version.substr(0, 5) == "HTTP/" && version[6] == '.')
    return reject(505, "HTTP version not supported: only HTTP/1.0 and HTTP/1.1");
  else
    return reject(400, "malformed request line: the version is not 'HTTP/1.x'");
  if (method == "GET")
    req.method = Method::Get;
  else if (method == "HEAD")
    req.method = Method::Head;
  else
    return reject(405, "only GET and HEAD are served");
  if (target.empty() || target.front() != '/')
    return reject(400, "the target must be an absolute path (origin form)");
  if (target.substr(0, target.find('?')) != "/metrics")
    return reject(404, "not found: the only resource is /metrics");
  return {};
}

}  // namespace

bool accepts_openmetrics(std::string_view accept) noexcept {
  while (!accept.empty()) {
    const auto comma = accept.find(',');
    std::string_view range = accept.substr(0, comma);
    accept = comma == std::string_view::npos ? std::string_view() : accept.substr(comma + 1);
    const auto semi = range.find(';');
    const std::string_view type = trim(range.substr(0, semi));
    if (!iequals(type, "application/openmetrics-text")) continue;
    bool zero = false;
    std::string_view params =
        semi == std::string_view::npos ? std::string_view() : range.substr(semi);
    while (!params.empty()) {
      params.remove_prefix(1);  // ';'
      const auto next = params.find(';');
      const std::string_view p = trim(params.substr(0, next));
      params = next == std::string_view::npos ? std::string_view() : params.substr(next);
      if (p.size() >= 2 && (p[0] == 'q' || p[0] == 'Q') && p[1] == '=') {
        // q=0, q=0.0, q=0.000: refused explicitly.
        const std::string_view q = p.substr(2);
        zero = !q.empty() && q.find_first_not_of("0.") == std::string_view::npos;
      }
    }
    if (!zero) return true;
  }
  return false;
}

ParseResult parse_request(std::string_view bytes, std::size_t limit) noexcept {
  const auto line_end = bytes.find("\r\n");
  if (line_end == std::string_view::npos) {
    if (auto r = check_partial_line(bytes); r.state == State::Rejected) return r;
    if (bytes.find('\n') != std::string_view::npos)
      return reject(400, "malformed request: lines must end with CRLF");
    if (bytes.size() >= limit) return reject(431, "request line longer than the 8 KiB limit");
    return {};
  }
  HttpRequest req;
  const std::string_view line = bytes.substr(0, line_end);
  if (line.find('\n') != std::string_view::npos || line.find('\r') != std::string_view::npos)
    return reject(400, "malformed request: lines must end with CRLF");
  if (auto r = parse_request_line(line, req); r.state == State::Rejected) return r;

  // Header fields, one per CRLF line, up to the empty line.
  std::size_t pos = line_end + 2;
  bool host = false;
  for (;;) {
    const auto end = bytes.find("\r\n", pos);
    if (end == std::string_view::npos) {
      const std::string_view rest = bytes.substr(pos);
      // No CRLF in `rest`: any LF is bare, a CR is fine only as the last byte so far.
      const auto cr = rest.find('\r');
      if (rest.find('\n') != std::string_view::npos ||
          (cr != std::string_view::npos && cr + 1 != rest.size()))
        return reject(400, "malformed header section: lines must end with CRLF");
      if (bytes.size() >= limit) return reject(431, "request headers exceed the 8 KiB limit");
      return {};
    }
    if (end + 2 > limit) return reject(431, "request headers exceed the 8 KiB limit");
    const std::string_view field = bytes.substr(pos, end - pos);
    pos = end + 2;
    if (field.empty()) break;
    if (field.front() == ' ' || field.front() == '\t')
      return reject(400, "malformed header: obsolete line folding is not accepted");
    const auto colon = field.find(':');
    if (colon == std::string_view::npos || colon == 0)
      return reject(400, "malformed header: expected 'Name: value'");
    const std::string_view name = field.substr(0, colon);
    for (char c : name)
      if (!is_tchar(c)) return reject(400, "malformed header: the name is not a token");
    const std::string_view value = field.substr(colon + 1);
    for (char c : value)
      if (!is_vchar_or_ws(c)) return reject(400, "malformed header: control byte in a value");
    const std::string_view v = trim(value);
    if (iequals(name, "Host")) {
      if (host) return reject(400, "more than one Host header");
      host = true;
    } else if (iequals(name, "Content-Length")) {
      if (v != "0") return reject(413, "a request body is not accepted (GET/HEAD /metrics)");
    } else if (iequals(name, "Transfer-Encoding")) {
      return reject(413, "a request body is not accepted (GET/HEAD /metrics)");
    } else if (iequals(name, "Accept")) {
      // Several Accept fields form one list.
      if (accepts_openmetrics(v)) req.format = Format::OpenMetrics;
    }
  }
  if (!host && !req.http10) return reject(400, "HTTP/1.1 request without a Host header");
  ParseResult r;
  r.state = State::Complete;
  r.request = req;
  r.consumed = pos;
  return r;
}

std::string_view status_text(int status) noexcept {
  switch (status) {
    case 200:
      return "OK";
    case 400:
      return "Bad Request";
    case 404:
      return "Not Found";
    case 405:
      return "Method Not Allowed";
    case 408:
      return "Request Timeout";
    case 413:
      return "Content Too Large";
    case 431:
      return "Request Header Fields Too Large";
    case 500:
      return "Internal Server Error";
    case 503:
      return "Service Unavailable";
    case 505:
      return "HTTP Version Not Supported";
  }
  return "Error";
}

}  // namespace ds1928::metrics
