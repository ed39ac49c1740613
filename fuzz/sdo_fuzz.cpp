// SDO client and server state machines fed with arbitrary SDO frames from their peer, with time
// moving on between frames. The input is a series of chunks: [selector, length, bytes...]. The
// selector picks the receiver (client or server), whether the chunk is a whole frame through
// parse_frame or the SDO layers (sequence, command, payload) behind a valid ASnd header, how
// much time passes, and when the client starts a new transfer.
#include <array>
#include <cstdlib>
#include <map>
#include <variant>
#include <vector>

#include "fuzz_input.hpp"
#include "powerlink/sdo.hpp"

using namespace ds1928::powerlink;

namespace {

struct Dictionary : SdoObjectAccess {
  std::map<std::pair<uint16_t, uint8_t>, std::vector<uint8_t>> objects;
  uint32_t read_object(uint16_t index, uint8_t sub, std::span<uint8_t> out,
                       std::size_t& size) noexcept override {
    // Objects of every size up to the transfer limit, also ones larger than `out`.
    const std::size_t want = (static_cast<std::size_t>(index) * 7u + sub) % (kMaxSdoTransfer + 8);
    if (auto it = objects.find({index, sub}); it != objects.end()) {
      if (it->second.size() > out.size()) return 0x08000000;
      std::copy(it->second.begin(), it->second.end(), out.begin());
      size = it->second.size();
      return 0;
    }
    if (want > out.size()) return 0x06070010;
    for (std::size_t i = 0; i < want; ++i) out[i] = static_cast<uint8_t>(i);
    size = want;
    return 0;
  }
  uint32_t write_object(uint16_t index, uint8_t sub,
                        std::span<const uint8_t> data) noexcept override {
    if (index == 0x1000) return 0x06010002;  // read-only
    if (objects.size() < 64) objects[{index, sub}].assign(data.begin(), data.end());
    return 0;
  }
};

std::vector<uint8_t> header_template(uint8_t src, uint8_t dst) {
  std::array<uint8_t, kMaxFrameSize> buf{};
  Sdo sdo;
  auto len = build_sdo(buf, asnd_header(MacAddress{2, 0, 0, 0, 0, src}, src, dst), sdo);
  if (!len) std::abort();
  return {buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(kSdoSeqOffset)};
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  static const std::vector<uint8_t> to_server = header_template(kNodeMn, 1);
  static const std::vector<uint8_t> to_client = header_template(1, kNodeMn);
  Dictionary dict;
  std::size_t sent = 0;
  int completions = 0;
  const FrameSink sink = [&](std::span<const uint8_t> f) {
    // Whatever the state machines send must itself be a valid SDO frame.
    auto a = parse_asnd(f);
    if (!a || !std::holds_alternative<Sdo>(a->body)) std::abort();
    ++sent;
  };
  SdoClient client({.node = 1,
                    .own_node = kNodeMn,
                    .own_mac = {},
                    .timeout_ns = 1'000'000,
                    .max_segment = kMaxSdoSegment - 4},
                   sink, [&](std::error_code, std::span<const uint8_t> d) {
                     if (d.size() > kMaxSdoTransfer) std::abort();
                     ++completions;
                   });
  SdoServer server({.own_node = 1,
                    .own_mac = {},
                    .client_node = kNodeMn,
                    .timeout_ns = 1'000'000,
                    .max_segment = kMaxSdoSegment - 4},
                   dict, sink);

  ds1928::fuzz::Input in(data, size);
  int64_t now = 0;
  std::array<uint8_t, kMaxFrameSize> frame{};
  std::array<uint8_t, kMaxSdoTransfer + 8> write_data{};
  for (std::size_t i = 0; i < write_data.size(); ++i) write_data[i] = static_cast<uint8_t>(i * 3);
  while (!in.empty()) {
    const uint8_t sel = in.u8();
    const bool for_server = sel & 1;
    const bool raw = sel & 2;
    now += (sel >> 4) * 100'000;  // up to 1.5 ms per chunk: timeouts fire too
    if (sel & 4) {
      const uint16_t index = in.u16();
      const uint8_t sub = in.u8();
      if (sel & 8)
        (void)client.write(index, sub, std::span(write_data).first(in.u16() % write_data.size()),
                           now);
      else
        (void)client.read(index, sub, now);
      continue;
    }
    const std::size_t n = in.u16() % (kMaxFrameSize + 1);
    const auto body = in.bytes(n);
    std::span<const uint8_t> whole;
    if (raw) {
      whole = body;
    } else {
      const auto& head = for_server ? to_server : to_client;
      frame.fill(0);
      std::copy(head.begin(), head.end(), frame.begin());
      const std::size_t room = std::min(body.size(), kMaxFrameSize - head.size());
      std::copy_n(body.begin(), room, frame.begin() + static_cast<std::ptrdiff_t>(head.size()));
      whole = std::span<const uint8_t>(frame).first(std::max(kMinFrameSize, head.size() + room));
    }
    if (auto a = parse_asnd(whole)) {
      if (const auto* sdo = std::get_if<Sdo>(&a->body)) {
        if (for_server)
          server.receive(*sdo, now);
        else
          client.receive(*sdo, now);
      }
    }
    client.tick(now);
    server.tick(now);
  }
  client.reset();
  server.reset();
  (void)sent;
  (void)completions;
  return 0;
}
