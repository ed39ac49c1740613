// ExpeditedSdoClient, the pure state machine of one expedited SDO transfer: the answer, the
// timeout on the caller's clock (a late answer is then no transfer's), an abort from the node, a
// segmented answer (not supported: every register is 1..4 bytes, so there is no toggle bit),
// another size, a second transfer while one is in flight, frames that are not the answer.
#include "canio/sdo_client.hpp"

#include <catch2/catch.hpp>
#include <vector>

using namespace ds1928::canio;

namespace {

constexpr int64_t kTimeout = 100'000'000;  // 100 ms
constexpr int64_t kT0 = 5'000'000'000;

CanFrame answer(uint32_t id, std::vector<uint8_t> bytes) {
  return make_standard_frame(id, bytes);
}

}  // namespace

TEST_CASE("SDO client: a read is answered with its value and size", "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  auto req = client.read(3, 0x2001, 0x10, 2, kT0);
  REQUIRE(req);
  CHECK(req->id == 0x603);
  CHECK(req->data[0] == 0x40);
  CHECK(client.busy());
  CHECK(client.deadline_ns() == kT0 + kTimeout);
  // Another node's answer and an error frame are not this transfer's.
  CHECK_FALSE(client.receive(answer(0x584, {0x4B, 0x01, 0x20, 0x10, 0x34, 0x12, 0, 0})));
  CanFrame error_frame = answer(0x583, {0x4B, 0x01, 0x20, 0x10, 0x34, 0x12, 0, 0});
  error_frame.error = true;
  CHECK_FALSE(client.receive(error_frame));
  CHECK(client.busy());
  auto out = client.receive(answer(0x583, {0x4B, 0x01, 0x20, 0x10, 0x34, 0x12, 0, 0}));
  REQUIRE(out);
  CHECK_FALSE(out->error);
  CHECK_FALSE(out->timed_out);
  CHECK(out->value == 0x1234);
  CHECK(out->size == 2);
  CHECK_FALSE(client.busy());
}

TEST_CASE("SDO client: a write is acknowledged", "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  auto req = client.write(1, 0x2001, 0x05, 1, 3, kT0);
  REQUIRE(req);
  CHECK(req->data[0] == 0x2F);
  CHECK(req->data[4] == 3);
  auto out = client.receive(answer(0x581, {0x60, 0x01, 0x20, 0x05, 0, 0, 0, 0}));
  REQUIRE(out);
  CHECK_FALSE(out->error);
}

TEST_CASE("SDO client: no answer times out on the caller's clock, a late answer is dropped",
          "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  REQUIRE(client.read(1, 0x2001, 0x05, 1, kT0));
  CHECK_FALSE(client.tick(kT0));
  CHECK_FALSE(client.tick(kT0 + kTimeout - 1));
  CHECK(client.busy());
  auto out = client.tick(kT0 + kTimeout);
  REQUIRE(out);
  CHECK(out->timed_out);
  CHECK_FALSE(out->error);
  CHECK_FALSE(client.busy());
  CHECK_FALSE(client.tick(kT0 + 2 * kTimeout));  // once
  // The answer that comes after the timeout belongs to no transfer.
  CHECK_FALSE(client.receive(answer(0x581, {0x4F, 0x01, 0x20, 0x05, 3, 0, 0, 0})));
  // The next transfer has its own deadline.
  REQUIRE(client.read(1, 0x2001, 0x06, 1, kT0 + 3 * kTimeout));
  CHECK_FALSE(client.tick(kT0 + 4 * kTimeout - 1));
  CHECK(client.tick(kT0 + 4 * kTimeout));
}

TEST_CASE("SDO client: an abort from the node ends the transfer with its code",
          "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  REQUIRE(client.write(1, 0x2001, 0x07, 1, 9, kT0));
  // 0x06090030: value range of parameter exceeded.
  auto out = client.receive(answer(0x581, {0x80, 0x01, 0x20, 0x07, 0x30, 0x00, 0x09, 0x06}));
  REQUIRE(out);
  CHECK(out->error.category() == ds1928::sdo_abort_category());
  CHECK(static_cast<uint32_t>(out->error.value()) == 0x0609'0030);
  CHECK_THAT(out->error.message(), Catch::Contains("0x06090030"));
  CHECK_FALSE(client.busy());
}

TEST_CASE("SDO client: a segmented answer is an error naming it (expedited only)",
          "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  REQUIRE(client.read(1, 0x1008, 0x00, 0, kT0));
  // Initiate upload response, not expedited, size indicated (20 bytes): a segmented transfer
  // would follow with toggled upload-segment requests; no register needs one.
  auto out = client.receive(answer(0x581, {0x41, 0x08, 0x10, 0x00, 20, 0, 0, 0}));
  REQUIRE(out);
  CHECK(out->error == SdoFrameError::kSegmentedNotSupported);
  CHECK_FALSE(client.busy());
}

TEST_CASE("SDO client: another size than expected is reported with what was answered",
          "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  REQUIRE(client.read(1, 0x2001, 0x05, 1, kT0));
  auto out = client.receive(answer(0x581, {0x43, 0x01, 0x20, 0x05, 5, 0, 0, 0}));
  REQUIRE(out);
  CHECK(out->error == SdoFrameError::kSizeMismatch);
  CHECK(out->size == 4);
  CHECK(out->value == 5);
  // An answer naming another object is an error of this transfer too (never taken as its value).
  REQUIRE(client.read(1, 0x2001, 0x05, 1, kT0));
  out = client.receive(answer(0x581, {0x4F, 0x01, 0x20, 0x06, 5, 0, 0, 0}));
  REQUIRE(out);
  CHECK(out->error == SdoFrameError::kSubindexMismatch);
}

TEST_CASE("SDO client: one transfer at a time, invalid requests refused", "[canio][sdo][client]") {
  ExpeditedSdoClient client(kTimeout);
  REQUIRE(client.read(1, 0x2001, 0x05, 1, kT0));
  auto second = client.write(1, 0x2001, 0x06, 1, 0, kT0);
  CHECK_FALSE(second);
  CHECK(second.error() == std::errc::operation_in_progress);
  CHECK(client.busy());
  client.cancel();
  CHECK_FALSE(client.busy());
  CHECK(client.read(0, 0x2001, 0x05, 1, kT0).error() == SdoFrameError::kInvalidNode);
  CHECK(client.write(1, 0x2001, 0x05, 5, 0, kT0).error() == SdoFrameError::kInvalidSize);
  CHECK_FALSE(client.busy());
}
