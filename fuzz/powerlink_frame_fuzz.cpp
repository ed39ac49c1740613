// POWERLINK frame parser: any received Ethernet frame. Whatever parses is read field by field
// (status entries included) and must respect the codec's own limits.
#include <cstdlib>
#include <variant>

#include "powerlink/frames.hpp"

using namespace ds1928::powerlink;

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

uint64_t touch(std::span<const uint8_t> s, std::span<const uint8_t> frame) {
  // A view must lie inside the frame it came from.
  check(s.empty() ||
        (s.data() >= frame.data() && s.data() + s.size() <= frame.data() + frame.size()));
  uint64_t sum = 0;
  for (uint8_t b : s) sum += b;
  return sum;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const uint8_t> frame(data, size);
  volatile uint64_t sink = 0;
  if (auto f = parse_frame(frame)) {
    // Short (unpadded) frames are accepted when their message is complete: never less than
    // the header, and for the fixed-size messages never less than the message.
    check(size > kHeaderSize && size <= kMaxFrameSize);
    std::visit(
        [&](const auto& m) {
          using T = std::decay_t<decltype(m)>;
          if constexpr (std::is_same_v<T, Soc>) {
            check(size >= kSocSize);
          } else if constexpr (std::is_same_v<T, SoA>) {
            check(size >= kSoaSize);
          } else if constexpr (std::is_same_v<T, PReq> || std::is_same_v<T, PRes>) {
            check(m.payload.size() <= kMaxIsoPayload);
            sink = sink + touch(m.payload, frame);
          } else if constexpr (std::is_same_v<T, Asnd>) {
            std::visit(
                [&](const auto& b) {
                  using B = std::decay_t<decltype(b)>;
                  if constexpr (std::is_same_v<B, StatusResponse>) {
                    sink = sink + touch(b.entries, frame);
                    for (std::size_t i = 0; i < b.entry_count(); ++i) sink = sink + b.entry(i).code;
                  } else if constexpr (std::is_same_v<B, Sdo>) {
                    sink = sink + touch(b.command.payload, frame);
                  } else if constexpr (std::is_same_v<B, NmtCommand> ||
                                       std::is_same_v<B, NmtRequest> ||
                                       std::is_same_v<B, AsndRaw>) {
                    sink = sink + touch(b.data, frame);
                  }
                },
                m.body);
          }
        },
        f->message);
  }
  (void)parse_soc(frame);
  (void)parse_preq(frame);
  (void)parse_pres(frame);
  (void)parse_soa(frame);
  (void)parse_asnd(frame);
  return 0;
}
