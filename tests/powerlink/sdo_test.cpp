#include "powerlink/sdo.hpp"

#include <catch2/catch.hpp>
#include <deque>
#include <map>
#include <vector>

using namespace ds1928::powerlink;
using ds1928::make_sdo_abort_error;

namespace {

struct Dictionary : SdoObjectAccess {
  std::map<std::pair<uint16_t, uint8_t>, std::vector<uint8_t>> objects;
  uint32_t read_object(uint16_t index, uint8_t sub, std::span<uint8_t> out,
                       std::size_t& size) noexcept override {
    auto it = objects.find({index, sub});
    if (it == objects.end()) return 0x06020000;
    if (it->second.size() > out.size()) return 0x08000000;
    std::copy(it->second.begin(), it->second.end(), out.begin());
    size = it->second.size();
    return 0;
  }
  uint32_t write_object(uint16_t index, uint8_t sub,
                        std::span<const uint8_t> data) noexcept override {
    if (index == 0x2001 && sub == 0x10) return 0x06010002;  // read-only
    objects[{index, sub}].assign(data.begin(), data.end());
    return 0;
  }
};

struct Bench {
  Dictionary dict;
  std::deque<std::vector<uint8_t>> to_server;
  std::deque<std::vector<uint8_t>> to_client;
  std::error_code result;
  std::vector<uint8_t> data;
  int completions = 0;
  bool drop_server_frames = false;
  std::size_t frames = 0;
  SdoClient client;
  SdoServer server;

  explicit Bench(std::size_t max_segment = kMaxSdoSegment - 4)
      : client(
            {.node = 1,
             .own_node = kNodeMn,
             .own_mac = {},
             .timeout_ns = 100'000'000,
             .max_segment = max_segment},
            [this](std::span<const uint8_t> f) { to_server.emplace_back(f.begin(), f.end()); },
            [this](std::error_code ec, std::span<const uint8_t> d) {
              result = ec;
              data.assign(d.begin(), d.end());
              ++completions;
            }),
        server({.own_node = 1,
                .own_mac = {},
                .client_node = kNodeMn,
                .timeout_ns = 100'000'000,
                .max_segment = max_segment},
               dict, [this](std::span<const uint8_t> f) {
                 if (!drop_server_frames) to_client.emplace_back(f.begin(), f.end());
               }) {}

  // Delivers queued frames one at a time (as the async slot would), through the codec.
  void pump(int64_t now = 0) {
    while (!to_server.empty() || !to_client.empty()) {
      if (!to_server.empty()) {
        auto f = std::move(to_server.front());
        to_server.pop_front();
        auto a = parse_asnd(f);
        REQUIRE(a);
        REQUIRE(f.size() >= 60);
        server.receive(std::get<Sdo>(a->body), now);
        ++frames;
      }
      if (!to_client.empty()) {
        auto f = std::move(to_client.front());
        to_client.pop_front();
        auto a = parse_asnd(f);
        REQUIRE(a);
        client.receive(std::get<Sdo>(a->body), now);
        ++frames;
      }
    }
  }
};

}  // namespace

TEST_CASE("SDO expedited write and read", "[powerlink][sdo]") {
  Bench b;
  const std::vector<uint8_t> value{0x34, 0x12};
  REQUIRE_FALSE(b.client.write(0x2001, 0x07, value, 0));
  CHECK(b.client.busy());
  CHECK(b.client.read(0x2001, 0x07, 0) == SdoError::kBusy);
  b.pump();
  REQUIRE(b.completions == 1);
  CHECK_FALSE(b.result);
  CHECK(b.dict.objects[{0x2001, 0x07}] == value);
  CHECK(b.server.connected());

  REQUIRE_FALSE(b.client.read(0x2001, 0x07, 0));
  b.pump();
  REQUIRE(b.completions == 2);
  CHECK_FALSE(b.result);
  CHECK(b.data == value);
  CHECK_FALSE(b.client.busy());
}

TEST_CASE("SDO segmented write and read", "[powerlink][sdo]") {
  Bench b(16);
  std::vector<uint8_t> big(300);
  for (std::size_t i = 0; i < big.size(); ++i) big[i] = static_cast<uint8_t>(i * 7);
  REQUIRE_FALSE(b.client.write(0x2002, 0x20, big, 0));
  b.pump();
  REQUIRE(b.completions == 1);
  CHECK_FALSE(b.result);
  CHECK(b.dict.objects[{0x2002, 0x20}] == big);
  CHECK(b.frames > 40);  // 304 bytes in 16-byte segments, each acknowledged

  b.dict.objects[{0x2002, 0x21}] = std::vector<uint8_t>(big.rbegin(), big.rend());
  REQUIRE_FALSE(b.client.read(0x2002, 0x21, 0));
  b.pump();
  REQUIRE(b.completions == 2);
  CHECK_FALSE(b.result);
  CHECK(b.data == std::vector<uint8_t>(big.rbegin(), big.rend()));
}

TEST_CASE("SDO aborts from the server arrive as abort codes", "[powerlink][sdo]") {
  Bench b;
  REQUIRE_FALSE(b.client.read(0x2005, 0x01, 0));
  b.pump();
  REQUIRE(b.completions == 1);
  CHECK(b.result == make_sdo_abort_error(0x06020000));
  CHECK(b.result.message().find("0x06020000") != std::string::npos);
  const std::vector<uint8_t> one{1};
  REQUIRE_FALSE(b.client.write(0x2001, 0x10, one, 0));
  b.pump();
  REQUIRE(b.completions == 2);
  CHECK(b.result == make_sdo_abort_error(0x06010002));
  // The connection survives an abort.
  REQUIRE_FALSE(b.client.write(0x2001, 0x01, one, 0));
  b.pump();
  CHECK(b.completions == 3);
  CHECK_FALSE(b.result);
}

TEST_CASE("SDO client times out, aborts and reconnects", "[powerlink][sdo]") {
  Bench b;
  b.drop_server_frames = true;
  REQUIRE_FALSE(b.client.read(0x2001, 0x01, 0));
  b.pump(0);
  b.client.tick(50'000'000);
  CHECK(b.completions == 0);
  b.client.tick(100'000'000);
  REQUIRE(b.completions == 1);
  CHECK(b.result == SdoError::kTimeout);
  CHECK_FALSE(b.client.busy());

  b.drop_server_frames = false;
  b.dict.objects[{0x2001, 0x01}] = {0x05};
  REQUIRE_FALSE(b.client.read(0x2001, 0x01, 200'000'000));
  b.pump(200'000'000);
  REQUIRE(b.completions == 2);
  CHECK_FALSE(b.result);
  CHECK(b.data == std::vector<uint8_t>{0x05});
}

TEST_CASE("SDO transfer fails with connection lost on node reset", "[powerlink][sdo]") {
  Bench b;
  REQUIRE_FALSE(b.client.read(0x2001, 0x01, 0));
  b.client.reset();
  REQUIRE(b.completions == 1);
  CHECK(b.result == SdoError::kConnectionLost);
}

TEST_CASE("an SDO abort without its 4-byte code is a protocol error, not a code read past it",
          "[powerlink][sdo]") {
  for (std::size_t n = 0; n < 4; ++n) {
    Bench b;
    REQUIRE_FALSE(b.client.read(0x2005, 0x01, 0));  // no such object: the server aborts
    for (int step = 0; step < 100 && b.completions == 0; ++step) {
      if (!b.to_server.empty()) {
        auto f = std::move(b.to_server.front());
        b.to_server.pop_front();
        auto a = parse_asnd(f);
        REQUIRE(a);
        b.server.receive(std::get<Sdo>(a->body), 0);
      }
      if (!b.to_client.empty()) {
        auto f = std::move(b.to_client.front());
        b.to_client.pop_front();
        auto a = parse_asnd(f);
        REQUIRE(a);
        Sdo sdo = std::get<Sdo>(a->body);
        if (sdo.command.abort) sdo.command.payload = sdo.command.payload.first(n);
        b.client.receive(sdo, 0);
      }
    }
    INFO(n << " bytes of abort code");
    REQUIRE(b.completions == 1);
    CHECK(b.result == make_error_code(SdoError::kProtocol));
  }
}

TEST_CASE(
    "SDO server: a client's close and a bare acknowledgement without connection go "
    "unanswered",
    "[powerlink][sdo]") {
  // openPOWERLINK's MN closes its connection after a transfer and acknowledges a node it just
  // reset; an answer to either reaches it in a later async slot and ends its next connection.
  Bench b;
  const std::vector<uint8_t> one{1};
  REQUIRE_FALSE(b.client.write(0x2001, 0x07, one, 0));
  b.pump();
  REQUIRE(b.completions == 1);
  b.server.reset();  // the node was reset (NMTResetNode): its server has no connection
  Sdo close;
  close.sequence = {1, SdoRecvCon::kNone, 1, SdoSendCon::kNone};
  b.server.receive(close, 0);
  CHECK(b.to_client.empty());
  Sdo ack;
  ack.sequence = {1, SdoRecvCon::kValid, 1, SdoSendCon::kValid};
  b.server.receive(ack, 0);
  CHECK(b.to_client.empty());
  // A request with a command still learns there is no connection (and the client reopens).
  Sdo request = ack;
  request.has_command = true;
  request.command.command_id = static_cast<uint8_t>(SdoCommandId::kReadByIndex);
  b.server.receive(request, 0);
  CHECK(b.to_client.size() == 1);
}

TEST_CASE("the SDO segmenter cuts a transfer as EPSG DS 301 §6.3.2.4 lays out the segments",
          "[powerlink][sdo]") {
  using Seg = SdoSegmentation;
  SdoSegmenter s;
  SECTION("a transfer that fits one segment goes expedited, whole") {
    s.start(12);
    const auto a = s.next(12);
    CHECK(a.segmentation == Seg::kExpedited);
    CHECK(a.offset == 0);
    CHECK(a.length == 12);
    CHECK(s.done());
  }
  SECTION("an empty transfer is one expedited segment of no bytes") {
    s.start(0);
    const auto a = s.next(8);
    CHECK(a.segmentation == Seg::kExpedited);
    CHECK(a.length == 0);
    CHECK(s.done());
  }
  SECTION("a larger one: Initiate with the total size, Segment, Complete with the rest") {
    s.start(21);
    const auto a = s.next(8);
    CHECK(a.segmentation == Seg::kInitiate);
    CHECK(a.total_size == 21);
    CHECK((a.offset == 0 && a.length == 8));
    CHECK_FALSE(s.done());
    const auto b = s.next(8);
    CHECK(b.segmentation == Seg::kSegment);
    CHECK(b.total_size == 0);
    CHECK((b.offset == 8 && b.length == 8));
    const auto c = s.next(8);
    CHECK(c.segmentation == Seg::kComplete);
    CHECK((c.offset == 16 && c.length == 5));
    CHECK(s.done());
  }
  SECTION("an exact multiple ends with a full Complete segment, never an empty one") {
    s.start(16);
    CHECK(s.next(8).segmentation == Seg::kInitiate);
    const auto b = s.next(8);
    CHECK(b.segmentation == Seg::kComplete);
    CHECK(b.length == 8);
    CHECK(s.done());
  }
  SECTION("random sizes: the segments cover the transfer once, in order") {
    uint32_t x = 0x2545F491;
    for (int round = 0; round < 500; ++round) {
      x ^= x << 13, x ^= x >> 17, x ^= x << 5;
      const std::size_t size = x % (kMaxSdoTransfer + 1);
      const std::size_t max = 8 + (x >> 16) % (kMaxSdoSegment - 11);
      s.start(size);
      std::size_t covered = 0, segments = 0;
      do {
        const auto seg = s.next(max);
        REQUIRE(seg.offset == covered);
        REQUIRE(seg.length <= max);
        const bool first = segments == 0, last = s.done();
        if (first && last)
          REQUIRE(seg.segmentation == Seg::kExpedited);
        else if (first)
          REQUIRE((seg.segmentation == Seg::kInitiate && seg.total_size == size));
        else if (last)
          REQUIRE(seg.segmentation == Seg::kComplete);
        else
          REQUIRE(seg.segmentation == Seg::kSegment);
        covered += seg.length;
        ++segments;
      } while (!s.done());
      REQUIRE(covered == size);
    }
  }
}
