// Expedited SDO: the byte patterns of CiA 301 for read, write and abort, response matching with
// every way a response can fail to answer the request, and random round trips.
#include <catch2/catch.hpp>
#include <random>
#include <vector>

#include "canio/sdo_expedited.hpp"

using namespace ds1928::canio;

namespace {

CanFrame frame(uint32_t id, std::vector<uint8_t> bytes) {
  return make_standard_frame(id, bytes);
}

std::vector<uint8_t> bytes_of(const CanFrame& f) {
  return {f.data.begin(), f.data.begin() + f.dlc};
}

}  // namespace

TEST_CASE("SDO write of a 16-bit value: 2B request, 60 response", "[canio][sdo]") {
  // Producer heartbeat time 0x1017.0 = 1000 ms on node 5.
  auto req = build_sdo_request(5, {SdoCommand::DownloadRequest, 0x1017, 0, 2, 1000});
  REQUIRE(req);
  CHECK(req->id == 0x605);
  CHECK(bytes_of(*req) == std::vector<uint8_t>{0x2B, 0x17, 0x10, 0x00, 0xE8, 0x03, 0x00, 0x00});
  const CanFrame resp = frame(0x585, {0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0});
  auto m = match_sdo_response(5, parse_sdo(5, false, *req).value(), resp);
  REQUIRE(m);
  CHECK(m->command == SdoCommand::DownloadResponse);
}

TEST_CASE("SDO write sizes 1..4 use 2F / 2B / 27 / 23", "[canio][sdo]") {
  const uint8_t spec[] = {0x2F, 0x2B, 0x27, 0x23};
  for (uint8_t size = 1; size <= 4; ++size) {
    auto req = build_sdo_request(1, {SdoCommand::DownloadRequest, 0x2000, 1, size, 0xAABBCCDD});
    REQUIRE(req);
    CHECK(req->data[0] == spec[size - 1]);
    // Only `size` data bytes carry the value; the rest are zero.
    for (int i = 0; i < 4; ++i)
      CHECK(req->data[4 + i] == (i < size ? (0xAABBCCDD >> (8 * i)) & 0xFF : 0));
  }
}

TEST_CASE("SDO read of device type: 40 request, 43 response with 4 bytes", "[canio][sdo]") {
  auto req = build_sdo_request(1, {SdoCommand::UploadRequest, 0x1000, 0, 0, 0});
  REQUIRE(req);
  CHECK(req->id == 0x601);
  CHECK(bytes_of(*req) == std::vector<uint8_t>{0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0});
  // B&R CANopen bus controller: device type 0x000F0191 (CiA 401, DI/DO/AI/AO).
  const CanFrame resp = frame(0x581, {0x43, 0x00, 0x10, 0x00, 0x91, 0x01, 0x0F, 0x00});
  auto m = match_sdo_response(1, {SdoCommand::UploadRequest, 0x1000, 0, 0, 0}, resp, 4);
  REQUIRE(m);
  CHECK(m->command == SdoCommand::UploadResponse);
  CHECK(m->size == 4);
  CHECK(m->value == 0x000F0191);
}

TEST_CASE("SDO upload response sizes: 4F 1 byte, 4B 2 bytes, 47 3 bytes", "[canio][sdo]") {
  const SdoMessage req{SdoCommand::UploadRequest, 0x2100, 3, 0, 0};
  auto one =
      match_sdo_response(9, req, frame(0x589, {0x4F, 0x00, 0x21, 0x03, 0x7F, 0xEE, 0xEE, 0xEE}), 1);
  REQUIRE(one);
  CHECK(one->value == 0x7F);  // bytes past the size are ignored
  auto two =
      match_sdo_response(9, req, frame(0x589, {0x4B, 0x00, 0x21, 0x03, 0x20, 0x03, 0, 0}), 2);
  REQUIRE(two);
  CHECK(two->value == 800);
  auto three = match_sdo_response(9, req, frame(0x589, {0x47, 0x00, 0x21, 0x03, 1, 2, 3, 0}));
  REQUIRE(three);
  CHECK(three->size == 3);
  CHECK(three->value == 0x030201);
}

TEST_CASE("SDO abort: 80 with the abort code, reported with the standard's text", "[canio][sdo]") {
  const SdoMessage req{SdoCommand::UploadRequest, 0x2001, 1, 0, 0};
  const CanFrame abort = frame(0x581, {0x80, 0x01, 0x20, 0x01, 0x00, 0x00, 0x02, 0x06});
  auto m = match_sdo_response(1, req, abort);
  REQUIRE_FALSE(m);
  CHECK(m.error().category() == sdo_abort_category());
  CHECK(static_cast<uint32_t>(m.error().value()) == 0x06020000);
  CHECK(m.error().message() ==
        "SDO abort 0x06020000: object does not exist in the object dictionary");
  // The client's own abort frame.
  auto own = build_sdo_request(1, {SdoCommand::Abort, 0x2001, 1, 0, 0x05040000});
  REQUIRE(own);
  CHECK(bytes_of(*own) == std::vector<uint8_t>{0x80, 0x01, 0x20, 0x01, 0x00, 0x00, 0x04, 0x05});
  CHECK(std::string(sdo_abort_text(0x12345678)) == "unknown abort code");
}

TEST_CASE("a response that does not answer the request is an error naming why", "[canio][sdo]") {
  const SdoMessage read{SdoCommand::UploadRequest, 0x2001, 1, 0, 0};
  const SdoMessage write{SdoCommand::DownloadRequest, 0x2001, 1, 2, 5};
  const auto ok_read = std::vector<uint8_t>{0x4B, 0x01, 0x20, 0x01, 5, 0, 0, 0};
  CHECK(match_sdo_response(1, read, frame(0x582, ok_read)).error() == SdoFrameError::kWrongCobId);
  CHECK(match_sdo_response(1, read, frame(0x601, ok_read)).error() == SdoFrameError::kWrongCobId);
  CHECK(match_sdo_response(1, read, frame(0x581, {0x4B, 0x01, 0x20, 0x01, 5})).error() ==
        SdoFrameError::kWrongLength);
  CHECK(match_sdo_response(1, read, frame(0x581, {0x4B, 0x02, 0x20, 0x01, 5, 0, 0, 0})).error() ==
        SdoFrameError::kIndexMismatch);
  CHECK(match_sdo_response(1, read, frame(0x581, {0x4B, 0x01, 0x20, 0x02, 5, 0, 0, 0})).error() ==
        SdoFrameError::kSubindexMismatch);
  CHECK(match_sdo_response(1, read, frame(0x581, {0x60, 0x01, 0x20, 0x01, 0, 0, 0, 0})).error() ==
        SdoFrameError::kCommandMismatch);
  CHECK(match_sdo_response(1, write, frame(0x581, ok_read)).error() ==
        SdoFrameError::kCommandMismatch);
  CHECK(match_sdo_response(1, read, frame(0x581, ok_read), 4).error() ==
        SdoFrameError::kSizeMismatch);
  CHECK(match_sdo_response(1, read, frame(0x581, {0x41, 0x01, 0x20, 0x01, 20, 0, 0, 0})).error() ==
        SdoFrameError::kSegmentedNotSupported);
  CHECK(match_sdo_response(1, read, frame(0x581, {0xE0, 0x01, 0x20, 0x01, 0, 0, 0, 0})).error() ==
        SdoFrameError::kUnknownCommand);
  CanFrame rtr = frame(0x581, {});
  rtr.rtr = true;
  CHECK(match_sdo_response(1, read, rtr).error() == SdoFrameError::kRemoteOrErrorFrame);
  CHECK(match_sdo_response(0, read, frame(0x580, ok_read)).error() == SdoFrameError::kInvalidNode);
  CHECK(build_sdo_request(128, read).error() == SdoFrameError::kInvalidNode);
  CHECK(build_sdo_request(1, {SdoCommand::DownloadRequest, 1, 1, 5, 0}).error() ==
        SdoFrameError::kInvalidSize);
  CHECK(build_sdo_request(1, {SdoCommand::DownloadRequest, 1, 1, 0, 0}).error() ==
        SdoFrameError::kInvalidSize);
  CHECK(build_sdo_response(1, read).error() == SdoFrameError::kCommandMismatch);
  CHECK(match_sdo_response(1, read, frame(0x581, ok_read)).error().message().find("index") ==
        std::string::npos);  // matched: no error
  CHECK(make_error_code(SdoFrameError::kSubindexMismatch).message() ==
        "SDO response names another subindex than the request");
}

TEST_CASE("random SDO exchanges round-trip, random frames are parsed or named",
          "[canio][sdo][random]") {
  std::mt19937_64 rng(0x5D0);
  for (int i = 0; i < 20000; ++i) {
    const auto node = static_cast<uint8_t>(1 + rng() % 127);
    const auto size = static_cast<uint8_t>(1 + rng() % 4);
    const auto index = static_cast<uint16_t>(rng());
    const auto sub = static_cast<uint8_t>(rng());
    const auto value = static_cast<uint32_t>(rng()) & (size == 4 ? ~0u : (1u << (8 * size)) - 1);
    const bool write = rng() & 1;
    const SdoMessage req = write ? SdoMessage{SdoCommand::DownloadRequest, index, sub, size, value}
                                 : SdoMessage{SdoCommand::UploadRequest, index, sub, 0, 0};
    auto rf = build_sdo_request(node, req);
    REQUIRE(rf);
    REQUIRE(rf->id == 0x600u + node);
    auto parsed = parse_sdo(node, false, *rf);
    REQUIRE(parsed);
    REQUIRE(*parsed == req);
    const SdoMessage resp = write ? SdoMessage{SdoCommand::DownloadResponse, index, sub, 0, 0}
                                  : SdoMessage{SdoCommand::UploadResponse, index, sub, size, value};
    auto sf = build_sdo_response(node, resp);
    REQUIRE(sf);
    REQUIRE(sf->id == 0x580u + node);
    auto m = match_sdo_response(node, req, *sf, write ? 0 : size);
    REQUIRE(m);
    REQUIRE(*m == resp);
  }
  for (int i = 0; i < 50000; ++i) {
    CanFrame f;
    f.id = 0x580 + 7;
    f.dlc = static_cast<uint8_t>(rng() % 9);
    const uint64_t d = rng();
    std::memcpy(f.data.data(), &d, 8);
    auto p = parse_sdo(7, true, f);
    if (p) {
      REQUIRE(f.dlc == 8);
      if (p->command == SdoCommand::UploadResponse) REQUIRE((p->size >= 1 && p->size <= 4));
    } else {
      REQUIRE(p.error().category() == sdo_frame_category());
    }
  }
}
