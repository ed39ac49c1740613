// The metrics endpoint's HTTP request parser: bytes as a client sends them, fed whole and in
// every split the server may see (a read ending anywhere). Checks the parser's promises: a
// verdict never changes once given for a prefix, a complete request consumes at most the input,
// a refusal carries a status and a reason.
#include <cstdlib>
#include <string_view>

#include "metrics/http_request.hpp"

using namespace ds1928::metrics;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  // The server's buffer holds kMaxRequestBytes: the parser never sees more.
  if (size > kMaxRequestBytes) size = kMaxRequestBytes;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const ParseResult whole = parse_request(bytes);
  if (whole.state == ParseResult::State::Complete && whole.consumed > size) std::abort();
  if (whole.state == ParseResult::State::Rejected && (whole.status < 400 || whole.reason.empty()))
    std::abort();
  // A prefix that was already decided decides the whole the same way (the server stops reading
  // at the first verdict).
  for (std::size_t n = 0; n < size; n += 1 + n / 8) {
    const ParseResult part = parse_request(bytes.substr(0, n));
    if (part.state == ParseResult::State::Incomplete) continue;
    if (part.state != whole.state || part.status != whole.status) std::abort();
    break;
  }
  return 0;
}
