// PollResponse Chaining frames: SyncRequest (SoA service 6) and SyncResponse (ASnd service 6),
// byte for byte, truncation, randomized round trips, and Wireshark's decoding of both.
#include "powerlink/sync_frames.hpp"

#include <unistd.h>

#include <catch2/catch.hpp>
#include <random>
#include <string>
#include <vector>

#include "pcap_util.hpp"

namespace pl = ds1928::powerlink;

namespace {
const pl::MacAddress kMnMac{0x02, 0, 0, 0, 0, 0xF0};
const pl::MacAddress kCnMac{0x02, 0, 0, 0, 0x19, 0x28};
}  // namespace

TEST_CASE("SyncRequest: SoA service 6 with its payload at bytes 24-53", "[powerlink][prc]") {
  pl::SyncRequest req;
  req.target = 3;
  req.sync_control = pl::sync_control::kPResModeSet | pl::sync_control::kPResTimeFirstValid |
                     pl::sync_control::kPResFallBackTimeoutValid |
                     pl::sync_control::kDestMacAddressValid;
  req.pres_time_first_ns = 0x11223344;
  req.pres_fallback_timeout_ns = 1'000'000 + 300'000;
  req.dest_mac = kCnMac;
  std::array<uint8_t, 64> out{};
  auto len = pl::build_sync_request(out, pl::soa_header(kMnMac), req);
  REQUIRE(len);
  CHECK(*len == 60);
  CHECK(out[14] == 0x05);  // SoA
  CHECK(out[20] == 0x06);  // RequestedServiceID SyncRequest
  CHECK(out[21] == 3);
  CHECK(out[24] == 0x31);  // SyncControl 0x80000031, little endian
  CHECK(out[27] == 0x80);
  CHECK(out[28] == 0x44);
  CHECK(out[31] == 0x11);
  CHECK(pl::load_le32(&out[44]) == 1'300'000);
  CHECK(std::equal(kCnMac.begin(), kCnMac.end(), out.begin() + 48));
  auto back = pl::parse_sync_request(std::span<const uint8_t>(out.data(), *len));
  REQUIRE(back);
  CHECK(back->target == 3);
  CHECK(back->sync_control == req.sync_control);
  CHECK(back->pres_time_first_ns == req.pres_time_first_ns);
  CHECK(back->pres_fallback_timeout_ns == req.pres_fallback_timeout_ns);
  CHECK(back->dest_mac == kCnMac);
  // An unpadded sender's frame that ends inside the payload is refused by name.
  auto short_frame = pl::parse_sync_request(std::span<const uint8_t>(out.data(), 50));
  REQUIRE_FALSE(short_frame);
  CHECK(short_frame.error() == make_error_code(pl::FrameError::kSyncRequestTruncated));
  // A SoA of another service is not a SyncRequest.
  pl::SoA soa;
  soa.service = pl::RequestedService::kStatusRequest;
  soa.target = 3;
  len = pl::build_soa(out, pl::soa_header(kMnMac), soa);
  REQUIRE(len);
  auto other = pl::parse_sync_request(std::span<const uint8_t>(out.data(), *len));
  REQUIRE_FALSE(other);
  CHECK(other.error() == make_error_code(pl::FrameError::kWrongMessageType));
}

TEST_CASE("SyncResponse: ASnd service 6, fields at bytes 20-43", "[powerlink][prc]") {
  pl::SyncResponse res;
  res.sync_status = pl::sync_status::kPResModeStatus | pl::sync_status::kPResTimeFirstValid;
  res.latency_ns = 10'000;
  res.sync_node_number = 2;
  res.sync_delay_ns = 12'345;
  res.pres_time_first_ns = 7'120;
  std::array<uint8_t, 64> out{};
  auto len = pl::build_sync_response(out, pl::asnd_header(kCnMac, 3, pl::kNodeMn), res);
  REQUIRE(len);
  CHECK(*len == 60);
  CHECK(out[14] == 0x06);
  CHECK(out[15] == pl::kNodeMn);
  CHECK(out[16] == 3);
  CHECK(out[17] == 0x06);
  CHECK(out[18] == 0);
  CHECK(pl::load_le32(&out[20]) == 0x80000001);
  CHECK(pl::load_le32(&out[24]) == 10'000);
  CHECK(pl::load_le32(&out[28]) == 2);
  CHECK(pl::load_le32(&out[32]) == 12'345);
  CHECK(pl::load_le32(&out[36]) == 7'120);
  // The generic parser carries it raw; the PRC parser reads the fields.
  auto frame = pl::parse_frame(std::span<const uint8_t>(out.data(), *len));
  REQUIRE(frame);
  const auto& asnd = std::get<pl::Asnd>(frame->message);
  const auto& raw = std::get<pl::AsndRaw>(asnd.body);
  auto back = pl::parse_sync_response(raw.data);
  REQUIRE(back);
  CHECK(back->sync_status == res.sync_status);
  CHECK(back->latency_ns == res.latency_ns);
  CHECK(back->sync_node_number == 2);
  CHECK(back->sync_delay_ns == 12'345);
  CHECK(back->pres_time_first_ns == 7'120);
  auto short_one = pl::parse_sync_response(raw.data.first(20));
  REQUIRE_FALSE(short_one);
  CHECK(short_one.error() == make_error_code(pl::FrameError::kSyncResponseTruncated));
}

TEST_CASE("Sync frames: randomized round trips", "[powerlink][prc]") {
  std::mt19937_64 rng(1928);
  std::array<uint8_t, 64> out{};
  for (int i = 0; i < 2000; ++i) {
    pl::SyncRequest req;
    req.target = static_cast<uint8_t>(1 + rng() % 239);
    req.sync_control = static_cast<uint32_t>(rng());
    req.pres_time_first_ns = static_cast<uint32_t>(rng());
    req.pres_time_second_ns = static_cast<uint32_t>(rng());
    req.sync_mn_delay_first_ns = static_cast<uint32_t>(rng());
    req.sync_mn_delay_second_ns = static_cast<uint32_t>(rng());
    req.pres_fallback_timeout_ns = static_cast<uint32_t>(rng());
    for (auto& b : req.dest_mac) b = static_cast<uint8_t>(rng());
    auto len = pl::build_sync_request(out, pl::soa_header(kMnMac), req);
    REQUIRE(len);
    auto back = pl::parse_sync_request(std::span<const uint8_t>(out.data(), *len));
    REQUIRE(back);
    CHECK(back->sync_control == req.sync_control);
    CHECK(back->pres_time_second_ns == req.pres_time_second_ns);
    CHECK(back->sync_mn_delay_first_ns == req.sync_mn_delay_first_ns);
    CHECK(back->sync_mn_delay_second_ns == req.sync_mn_delay_second_ns);
    CHECK(back->dest_mac == req.dest_mac);
    // Any truncation below 54 bytes is refused, never read past.
    const std::size_t cut = 23 + rng() % (pl::kSyncRequestSize - 23);
    CHECK_FALSE(pl::parse_sync_request(std::span<const uint8_t>(out.data(), cut)));
  }
}

TEST_CASE("Wireshark decodes SyncRequest, SyncResponse and a PResMN", "[powerlink][prc][tshark]") {
  if (access("/usr/bin/tshark", X_OK) != 0) {
    WARN("tshark not installed: Wireshark decoding check skipped");
    return;
  }
  std::vector<std::vector<uint8_t>> frames;
  std::array<uint8_t, 64> out{};
  pl::SyncRequest req;
  req.target = 1;
  req.sync_control = pl::sync_control::kPResModeSet | pl::sync_control::kPResTimeFirstValid |
                     pl::sync_control::kDestMacAddressValid;
  req.pres_time_first_ns = 8'000;
  req.dest_mac = kCnMac;
  auto len = pl::build_sync_request(out, pl::soa_header(kMnMac), req);
  REQUIRE(len);
  frames.emplace_back(out.begin(), out.begin() + static_cast<long>(*len));
  pl::SyncResponse res;
  res.sync_status = pl::sync_status::kPResModeStatus | pl::sync_status::kPResTimeFirstValid;
  res.latency_ns = 10'000;
  res.pres_time_first_ns = 8'000;
  len = pl::build_sync_response(out, pl::asnd_header(kCnMac, 1, pl::kNodeMn), res);
  REQUIRE(len);
  frames.emplace_back(out.begin(), out.begin() + static_cast<long>(*len));
  std::array<uint8_t, 36> pdo{};
  pl::PRes pres_mn;
  pres_mn.nmt_state = pl::NmtState::kOperational;
  pres_mn.payload = pdo;
  len = pl::build_pres(out, pl::pres_header(kMnMac, pl::kNodeMn), pres_mn);
  REQUIRE(len);
  frames.emplace_back(out.begin(), out.begin() + static_cast<long>(*len));
  const std::string path = DS1928_TEST_TMPDIR "/powerlink_prc_samples.pcap";
  ds1928::powerlink::test::write_pcap(path, frames);
  using ds1928::powerlink::test::run_command;
  const std::string verbose = run_command("tshark -n -r " + path + " -V 2>&1");
  INFO(verbose);
  CHECK(verbose.find("Malformed") == std::string::npos);
  CHECK(verbose.find("Expert Info (Error") == std::string::npos);
  const std::string fields = run_command(
      "tshark -n -r " + path +
      " -T fields -e epl.soa.svid -e epl.soa.prmst -e epl.soa.prft.end -e epl.soa.adva.end"
      " -e epl.asnd.svid -e epl.asnd.syncresponse.latency -e epl.asnd.syncresponse.pres.fst"
      " -e epl.asnd.syncresponse.mode -e epl.src 2>/dev/null");
  INFO(fields);
  CHECK(fields.find("8000") != std::string::npos);
  CHECK(fields.find("02:00:00:00:19:28") != std::string::npos);
  CHECK(fields.find("10000") != std::string::npos);
  // The third frame: a PRes from the MN (node 240).
  CHECK(fields.find("240") != std::string::npos);
}
