#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <random>
#include <vector>

#include "frame_samples.hpp"
#include "powerlink/frames.hpp"

using namespace ds1928::powerlink;
using ds1928::powerlink::test::kCnMac;
using ds1928::powerlink::test::kMnMac;

namespace {
std::vector<uint8_t> padded(std::initializer_list<uint8_t> bytes) {
  std::vector<uint8_t> v(bytes);
  if (v.size() < 60) v.resize(60, 0);
  return v;
}
}  // namespace

TEST_CASE("SoC bytes are built and parsed exactly", "[powerlink][codec]") {
  const auto wire =
      padded({0x01, 0x11, 0x1E, 0x00, 0x00, 0x01, 0x02, 0x00, 0x00, 0x00, 0x00, 0xF0,
              0x88, 0xAB, 0x01, 0xFF, 0xF0, 0x00, 0x80, 0x00, 0x78, 0x56, 0x34, 0x12,
              0xE8, 0x03, 0x00, 0x00, 0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01});
  std::array<uint8_t, kMaxFrameSize> buf{};
  buf.fill(0xEE);  // padding must be written, not left over
  Soc soc;
  soc.multiplexed_cycle_completed = true;
  soc.net_time = {0x12345678, 1000};
  soc.relative_time_us = 0x0102030405060708ULL;
  auto len = build_soc(buf, soc_header(kMnMac), soc);
  REQUIRE(len);
  REQUIRE(*len == 60);
  CHECK(std::equal(wire.begin(), wire.end(), buf.begin()));

  auto parsed = parse_soc(wire);
  REQUIRE(parsed);
  CHECK(parsed->multiplexed_cycle_completed);
  CHECK_FALSE(parsed->prescaled_slot);
  CHECK(parsed->net_time == NetTime{0x12345678, 1000});
  CHECK(parsed->relative_time_us == 0x0102030405060708ULL);
}

// The names the foreign-MN report and the logs give a frame: the standard's own (the frame
// header's MessageType, byte 14), and a value outside them named as a frame, not as one of them.
TEST_CASE("Message types are named as DS 301 writes them", "[powerlink][codec]") {
  CHECK(to_string(MessageType::kSoC) == "SoC");
  CHECK(to_string(MessageType::kPReq) == "PReq");
  CHECK(to_string(MessageType::kPRes) == "PRes");
  CHECK(to_string(MessageType::kSoA) == "SoA");
  CHECK(to_string(MessageType::kASnd) == "ASnd");
  CHECK(to_string(static_cast<MessageType>(0x00)) == "frame");
  CHECK(to_string(static_cast<MessageType>(0x02)) == "frame");
}

TEST_CASE("PRes bytes parse to state, flags and payload", "[powerlink][codec]") {
  // PRes from node 5, OPERATIONAL, RD + EN, PR 7 RS 2, payload 4 bytes.
  const auto wire =
      padded({0x01, 0x11, 0x1E, 0x00, 0x00, 0x02, 0x02, 0,    0,    0,    0,    5,    0x88, 0xAB,
              0x04, 0xFF, 0x05, 0xFD, 0x11, 0x3A, 0x20, 0x00, 0x04, 0x00, 0xDE, 0xAD, 0xBE, 0xEF});
  auto h = parse_header(wire);
  REQUIRE(h);
  CHECK(h->type == MessageType::kPRes);
  CHECK(h->src_node == 5);
  auto p = parse_pres(wire);
  REQUIRE(p);
  CHECK(p->nmt_state == NmtState::kOperational);
  CHECK(p->ready);
  CHECK(p->exception_new);
  CHECK_FALSE(p->multiplexed_slot);
  CHECK(p->priority == 7);
  CHECK(p->request_count == 2);
  CHECK(p->pdo_version == 0x20);
  REQUIRE(p->payload.size() == 4);
  CHECK(p->payload[0] == 0xDE);
  CHECK(p->payload[3] == 0xEF);

  std::array<uint8_t, kMaxFrameSize> buf{};
  auto len = build_pres(buf, pres_header({0x02, 0, 0, 0, 0, 5}, 5), *p);
  REQUIRE(len);
  CHECK(std::equal(wire.begin(), wire.end(), buf.begin()));
}

TEST_CASE("SoA, PReq, NMTCommand and SDO bytes", "[powerlink][codec]") {
  std::array<uint8_t, kMaxFrameSize> buf{};
  SoA soa;
  soa.mn_nmt_state = NmtState::kPreOperational1;
  soa.service = RequestedService::kIdentRequest;
  soa.target = 3;
  auto len = build_soa(buf, soa_header(kMnMac), soa);
  REQUIRE(len);
  CHECK(*len == 60);
  CHECK(buf[14] == 0x05);
  CHECK(buf[15] == 0xFF);
  CHECK(buf[16] == 0xF0);
  CHECK(buf[17] == 0x1D);
  CHECK(buf[20] == 0x01);
  CHECK(buf[21] == 3);
  CHECK(buf[22] == 0x20);
  CHECK(std::equal(kMacSoA.begin(), kMacSoA.end(), buf.begin()));

  const std::array<uint8_t, 3> payload{1, 2, 3};
  PReq preq;
  preq.ready = true;
  preq.exception_acknowledge = true;
  preq.payload = payload;
  len = build_preq(buf, preq_header(kMnMac, kCnMac, 9), preq);
  REQUIRE(len);
  CHECK(buf[14] == 0x03);
  CHECK(buf[15] == 9);
  CHECK(buf[18] == 0x05);
  CHECK(buf[22] == 3);
  CHECK(buf[23] == 0);
  CHECK(buf[24] == 1);
  CHECK(buf[26] == 3);
  CHECK(std::equal(kCnMac.begin(), kCnMac.end(), buf.begin()));

  len = build_nmt_command(buf, asnd_header(kMnMac, kNodeMn, 9),
                          {static_cast<uint8_t>(NmtCommandId::kEnableReadyToOperate), {}});
  REQUIRE(len);
  CHECK(buf[14] == 0x06);
  CHECK(buf[17] == 0x04);
  CHECK(buf[18] == 0x24);

  // Segmented write initiate: total size before the payload, segment size counts it.
  const std::array<uint8_t, 6> data{9, 8, 7, 6, 5, 4};
  Sdo sdo;
  sdo.sequence = {3, SdoRecvCon::kValid, 4, SdoSendCon::kValidAckRequest};
  sdo.has_command = true;
  sdo.command.transaction_id = 0x11;
  sdo.command.segmentation = SdoSegmentation::kInitiate;
  sdo.command.command_id = 0x01;
  sdo.command.total_size = 100;
  sdo.command.payload = data;
  len = build_sdo(buf, asnd_header(kMnMac, kNodeMn, 9), sdo);
  REQUIRE(len);
  CHECK(buf[17] == 0x05);
  CHECK(buf[18] == ((3 << 2) | 2));
  CHECK(buf[19] == ((4 << 2) | 3));
  CHECK(buf[23] == 0x11);
  CHECK(buf[24] == 0x10);
  CHECK(buf[25] == 0x01);
  CHECK(buf[26] == 10);
  CHECK(buf[30] == 100);
  CHECK(buf[34] == 9);
  auto parsed = parse_asnd(std::span<const uint8_t>(buf.data(), *len));
  REQUIRE(parsed);
  const auto& s = std::get<Sdo>(parsed->body);
  CHECK(s.has_command);
  CHECK(s.command.total_size == 100);
  REQUIRE(s.command.payload.size() == 6);
  CHECK(s.command.payload[5] == 4);
  CHECK(s.sequence.send_con == SdoSendCon::kValidAckRequest);
}

TEST_CASE("Parsing rejects short, long and inconsistent frames with a reason",
          "[powerlink][codec]") {
  const auto samples = ds1928::powerlink::test::build_samples();
  const auto& soc = samples.at(0).bytes;
  CHECK(parse_frame(std::span(soc).first(16)).error() == FrameError::kFrameTooShort);
  CHECK(parse_frame(std::span(soc).first(35)).error() == FrameError::kSocTruncated);
  std::vector<uint8_t> big(1515, 0);
  std::copy(soc.begin(), soc.end(), big.begin());
  CHECK(parse_frame(big).error() == FrameError::kFrameTooLong);

  auto bad = soc;
  bad[13] = 0x00;
  CHECK(parse_frame(bad).error() == FrameError::kNotPowerlink);
  bad = soc;
  bad[14] = 0x02;
  CHECK(parse_frame(bad).error() == FrameError::kUnknownMessageType);
  bad = soc;
  bad[16] = 5;  // SoC not from the MN
  CHECK(parse_frame(bad).error() == FrameError::kInvalidSourceNode);

  auto pres = samples.at(2).bytes;  // PRes with 46-byte payload in a 70-byte frame
  bad = pres;
  store_le16(&bad[22], 47);
  CHECK(parse_frame(bad).error() == FrameError::kPayloadSizeExceedsFrame);
  store_le16(&bad[22], 1491);
  CHECK(parse_frame(bad).error() == FrameError::kPayloadTooLarge);
  bad = pres;
  bad[17] = 0x42;
  CHECK(parse_frame(bad).error() == FrameError::kInvalidNmtState);
  bad = pres;
  bad[15] = 3;  // PRes must be multicast
  CHECK(parse_frame(bad).error() == FrameError::kInvalidDestinationNode);

  auto ident = samples.at(6).bytes;
  CHECK(parse_frame(std::span(ident).first(175)).error() == FrameError::kIdentResponseTruncated);
  bad = ident;
  bad[17] = 0x42;
  CHECK(parse_frame(bad).error() == FrameError::kUnknownServiceId);

  auto soa = samples.at(3).bytes;
  bad = soa;
  bad[20] = 0x07;
  CHECK(parse_frame(bad).error() == FrameError::kUnknownServiceId);
  bad = soa;
  bad[21] = 0;  // StatusRequest to nobody
  CHECK(parse_frame(bad).error() == FrameError::kInvalidDestinationNode);

  auto write = samples.at(11).bytes;
  bad = write;
  store_le16(&bad[26], 31);
  CHECK(parse_frame(bad).error() == FrameError::kSdoSegmentSizeExceedsFrame);
  auto abort = samples.at(14).bytes;
  bad = abort;
  store_le16(&bad[26], 2);
  CHECK(parse_frame(bad).error() == FrameError::kSdoInconsistentCommand);

  CHECK(parse_pres(soc).error() == FrameError::kWrongMessageType);
  CHECK(std::string(make_error_code(FrameError::kPayloadTooLarge).category().name()) ==
        "powerlink.frame");

  std::array<uint8_t, 59> small{};
  CHECK(build_soc(small, soc_header(kMnMac), Soc{}).error() == FrameError::kBufferTooSmall);
  std::vector<uint8_t> huge(1491);
  std::array<uint8_t, kMaxFrameSize> buf{};
  PReq preq;
  preq.payload = huge;
  CHECK(build_preq(buf, preq_header(kMnMac, kCnMac, 1), preq).error() ==
        FrameError::kPayloadTooLarge);
}

TEST_CASE("54-byte frames (unpadded software senders) are accepted when complete",
          "[powerlink][codec]") {
  // What a sender on a veth/TAP link puts on the wire without padding: 14-byte Ethernet header +
  // 40 bytes of POWERLINK. The SoC from an MN with NetTime 1 s + 500 ns, RelativeTime 4000 µs,
  // MC set.
  std::vector<uint8_t> soc = {0x01, 0x11, 0x1E, 0x00, 0x00, 0x01, 0x02, 0x00, 0x00,
                              0x00, 0x00, 0xF0, 0x88, 0xAB, 0x01, 0xFF, 0xF0, 0x00,
                              0x80, 0x00, 0x01, 0x00, 0x00, 0x00, 0xF4, 0x01, 0x00,
                              0x00, 0xA0, 0x0F, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
  soc.resize(54, 0);
  auto s = parse_soc(soc);
  REQUIRE(s);
  CHECK(s->multiplexed_cycle_completed);
  CHECK(s->net_time == NetTime{1, 500});
  CHECK(s->relative_time_us == 4000);
  CHECK(is_short_frame(soc.size()));

  // SoA: StatusRequest to node 7, MN PRE_OPERATIONAL_2.
  std::vector<uint8_t> soa = {0x01, 0x11, 0x1E, 0x00, 0x00, 0x03, 0x02, 0x00,
                              0x00, 0x00, 0x00, 0xF0, 0x88, 0xAB, 0x05, 0xFF,
                              0xF0, 0x5D, 0x00, 0x00, 0x02, 0x07, 0x20};
  soa.resize(54, 0);
  auto a = parse_soa(soa);
  REQUIRE(a);
  CHECK(a->mn_nmt_state == NmtState::kPreOperational2);
  CHECK(a->service == RequestedService::kStatusRequest);
  CHECK(a->target == 7);
  CHECK(a->epl_version == 0x20);

  // Every sample whose message fits 54 bytes parses to the same message cut to 54 bytes as with
  // its padding (PReq/PRes with ≤ 30 payload bytes, NMTCommand, SDO sequence-only, StatusResponse).
  std::array<uint8_t, kMaxFrameSize> buf{};
  std::array<uint8_t, 6> payload{1, 2, 3, 4, 5, 6};
  PReq preq;
  preq.ready = true;
  preq.payload = payload;
  PRes pres;
  pres.nmt_state = NmtState::kOperational;
  pres.payload = payload;
  NmtCommand cmd;
  cmd.command = static_cast<uint8_t>(NmtCommandId::kStartNode);
  Sdo seq;
  seq.sequence.recv_con = SdoRecvCon::kInit;
  seq.sequence.send_con = SdoSendCon::kInit;
  StatusResponse st;
  st.nmt_state = NmtState::kPreOperational2;
  std::vector<std::vector<uint8_t>> frames;
  auto keep = [&](ds1928::Result<std::size_t> len) {
    REQUIRE(len);
    frames.emplace_back(buf.begin(), buf.begin() + *len);
  };
  keep(build_preq(buf, preq_header(kMnMac, kCnMac, 3), preq));
  keep(build_pres(buf, pres_header(kCnMac, 3), pres));
  keep(build_nmt_command(buf, asnd_header(kMnMac, kNodeMn, 3), cmd));
  keep(build_sdo(buf, asnd_header(kCnMac, 3, kNodeMn), seq));
  keep(build_status_response(buf, asnd_header(kCnMac, 3, kNodeMn), st, {}));
  for (const auto& full : frames) {
    const std::vector<uint8_t> cut(full.begin(), full.begin() + 54);
    auto want = parse_frame(full);
    auto got = parse_frame(cut);
    REQUIRE(want);
    REQUIRE(got);
    CHECK(got->header.type == want->header.type);
    CHECK(got->message.index() == want->message.index());
  }
  auto p = parse_pres(std::span(frames[1]).first(54));
  REQUIRE(p);
  CHECK(std::equal(p->payload.begin(), p->payload.end(), payload.begin(), payload.end()));
  auto q = parse_preq(std::span(frames[0]).first(30));  // exactly header + payload
  REQUIRE(q);
  CHECK(q->payload.size() == 6);
  CHECK(q->ready);
  // An unpadded sequence-layer-only SDO frame ends after its 4 sequence bytes.
  auto sq = parse_asnd(std::span(frames[3]).first(22));
  REQUIRE(sq);
  CHECK_FALSE(std::get<Sdo>(sq->body).has_command);
  CHECK(std::get<Sdo>(sq->body).sequence.send_con == SdoSendCon::kInit);
}

TEST_CASE("Frames that end inside their message are refused with the message's error",
          "[powerlink][codec]") {
  const auto samples = ds1928::powerlink::test::build_samples();
  auto cut = [](const std::vector<uint8_t>& f, std::size_t n) {
    return parse_frame(std::span(f).first(n));
  };
  const auto& soc = samples.at(0).bytes;
  CHECK(cut(soc, 36));
  CHECK(cut(soc, 35).error() == FrameError::kSocTruncated);
  const auto& preq = samples.at(1).bytes;
  CHECK(cut(preq, 23).error() == FrameError::kPollTruncated);
  CHECK(cut(preq, 24 + load_le16(&preq[22]) - 1).error() == FrameError::kPayloadSizeExceedsFrame);
  CHECK(cut(preq, 24 + load_le16(&preq[22])));
  const auto& pres = samples.at(2).bytes;
  CHECK(cut(pres, 23).error() == FrameError::kPollTruncated);
  CHECK(cut(pres, 54).error() == FrameError::kPayloadSizeExceedsFrame);  // 46-byte payload
  const auto& soa = samples.at(3).bytes;
  CHECK(cut(soa, 23));
  CHECK(cut(soa, 22).error() == FrameError::kSoaTruncated);
  const auto& ident = samples.at(6).bytes;
  CHECK(cut(ident, 17).error() == FrameError::kAsndTruncated);
  CHECK(cut(ident, 54).error() == FrameError::kIdentResponseTruncated);
  for (const auto& sample : samples) {
    auto full = parse_frame(sample.bytes);
    REQUIRE(full);
    const auto* asnd = std::get_if<Asnd>(&full->message);
    if (asnd == nullptr) continue;
    if (asnd->service == AsndService::kStatusResponse) {
      CHECK(cut(sample.bytes, 31).error() == FrameError::kStatusResponseTruncated);
    } else if (asnd->service == AsndService::kNmtCommand) {
      CHECK(cut(sample.bytes, 19).error() == FrameError::kAsndTruncated);
    } else if (asnd->service == AsndService::kSdo) {
      CHECK(cut(sample.bytes, 21).error() == FrameError::kSdoTruncated);
      if (std::get<Sdo>(asnd->body).has_command)
        CHECK(cut(sample.bytes, 29).error() == FrameError::kSdoTruncated);
    }
  }
  // Every truncation error names its message.
  for (auto e : {FrameError::kSocTruncated, FrameError::kPollTruncated, FrameError::kSoaTruncated,
                 FrameError::kAsndTruncated, FrameError::kIdentResponseTruncated,
                 FrameError::kStatusResponseTruncated, FrameError::kSdoTruncated})
    CHECK(make_error_code(e).message().find("truncated") != std::string::npos);
}

TEST_CASE("StatusResponse error entries survive build and parse", "[powerlink][codec]") {
  const auto samples = ds1928::powerlink::test::build_samples();
  const auto& bytes = samples.at(7).bytes;
  CHECK(bytes.size() == 92);
  auto a = parse_asnd(bytes);
  REQUIRE(a);
  const auto& st = std::get<StatusResponse>(a->body);
  CHECK(st.exception_new);
  CHECK(st.nmt_state == NmtState::kPreOperational2);
  REQUIRE(st.entry_count() == 2);
  CHECK(st.entry(0).code == 0x8235);
  CHECK(st.entry(0).timestamp == 0x1122334455667788ULL);
  CHECK(st.entry(0).additional[7] == 8);
  CHECK(st.entry(1).code == 0x8700);
}

TEST_CASE("Randomized build/parse round trips", "[powerlink][codec]") {
  std::mt19937 rng(12345);
  auto u8 = [&] { return static_cast<uint8_t>(rng()); };
  std::array<uint8_t, kMaxFrameSize> buf{};
  std::vector<uint8_t> payload;
  for (int i = 0; i < 3000; ++i) {
    payload.resize(rng() % (kMaxIsoPayload + 1));
    for (auto& b : payload) b = u8();
    const uint8_t node = static_cast<uint8_t>(1 + rng() % 239);
    {
      PReq p;
      p.multiplexed_slot = rng() & 1;
      p.exception_acknowledge = rng() & 1;
      p.ready = rng() & 1;
      p.pdo_version = u8();
      p.payload = payload;
      auto len = build_preq(buf, preq_header(kMnMac, kCnMac, node), p);
      REQUIRE(len);
      CHECK(*len == std::max<std::size_t>(60, 24 + payload.size()));
      auto q = parse_preq(std::span<const uint8_t>(buf.data(), *len));
      REQUIRE(q);
      CHECK(q->multiplexed_slot == p.multiplexed_slot);
      CHECK(q->exception_acknowledge == p.exception_acknowledge);
      CHECK(q->ready == p.ready);
      CHECK(q->pdo_version == p.pdo_version);
      CHECK(std::equal(q->payload.begin(), q->payload.end(), payload.begin(), payload.end()));
    }
    {
      PRes p;
      p.nmt_state = (rng() & 1) ? NmtState::kOperational : NmtState::kPreOperational2;
      p.exception_new = rng() & 1;
      p.ready = rng() & 1;
      p.priority = u8() & 7;
      p.request_count = u8() & 7;
      p.payload = payload;
      auto len = build_pres(buf, pres_header(kCnMac, node), p);
      REQUIRE(len);
      auto q = parse_pres(std::span<const uint8_t>(buf.data(), *len));
      REQUIRE(q);
      CHECK(q->nmt_state == p.nmt_state);
      CHECK(q->exception_new == p.exception_new);
      CHECK(q->priority == p.priority);
      CHECK(q->request_count == p.request_count);
      CHECK(q->payload.size() == payload.size());
    }
    {
      Soc s;
      s.net_time = {static_cast<uint32_t>(rng()), static_cast<uint32_t>(rng())};
      s.relative_time_us = (static_cast<uint64_t>(rng()) << 32) | rng();
      s.prescaled_slot = rng() & 1;
      auto len = build_soc(buf, soc_header(kMnMac), s);
      REQUIRE(len);
      auto q = parse_soc(std::span<const uint8_t>(buf.data(), *len));
      REQUIRE(q);
      CHECK(q->net_time == s.net_time);
      CHECK(q->relative_time_us == s.relative_time_us);
      CHECK(q->prescaled_slot == s.prescaled_slot);
    }
    {
      IdentResponse r;
      r.vendor_id = static_cast<uint32_t>(rng());
      r.product_code = static_cast<uint32_t>(rng());
      r.poll_in_size = static_cast<uint16_t>(rng() % 1491);
      r.poll_out_size = static_cast<uint16_t>(rng() % 1491);
      r.serial_no = static_cast<uint32_t>(rng());
      r.host_name[0] = 'x';
      r.vendor_ext2[47] = u8();
      auto len = build_ident_response(buf, asnd_header(kCnMac, node, kNodeMn), r);
      REQUIRE(len);
      CHECK(*len == kIdentResponseSize);
      auto a = parse_asnd(std::span<const uint8_t>(buf.data(), *len));
      REQUIRE(a);
      const auto& q = std::get<IdentResponse>(a->body);
      CHECK(q.vendor_id == r.vendor_id);
      CHECK(q.product_code == r.product_code);
      CHECK(q.poll_in_size == r.poll_in_size);
      CHECK(q.poll_out_size == r.poll_out_size);
      CHECK(q.serial_no == r.serial_no);
      CHECK(q.host_name == r.host_name);
      CHECK(q.vendor_ext2 == r.vendor_ext2);
    }
    {
      Sdo s;
      s.sequence = {static_cast<uint8_t>(u8() & 63), static_cast<SdoRecvCon>(u8() & 3),
                    static_cast<uint8_t>(u8() & 63), static_cast<SdoSendCon>(u8() & 3)};
      s.has_command = true;
      s.command.transaction_id = u8();
      s.command.response = rng() & 1;
      s.command.segmentation = static_cast<SdoSegmentation>(u8() & 3);
      s.command.command_id = 1 + (u8() & 1);
      s.command.total_size = static_cast<uint32_t>(rng());
      const std::size_t n = std::min<std::size_t>(payload.size(), kMaxSdoSegment - 4);
      s.command.payload = std::span<const uint8_t>(payload.data(), n);
      auto len = build_sdo(buf, asnd_header(kMnMac, kNodeMn, node), s);
      REQUIRE(len);
      auto a = parse_asnd(std::span<const uint8_t>(buf.data(), *len));
      REQUIRE(a);
      const auto& q = std::get<Sdo>(a->body);
      CHECK(q.sequence.recv_seq == s.sequence.recv_seq);
      CHECK(q.sequence.send_seq == s.sequence.send_seq);
      CHECK(q.sequence.recv_con == s.sequence.recv_con);
      CHECK(q.sequence.send_con == s.sequence.send_con);
      CHECK(q.command.transaction_id == s.command.transaction_id);
      CHECK(q.command.response == s.command.response);
      CHECK(q.command.segmentation == s.command.segmentation);
      if (s.command.segmentation == SdoSegmentation::kInitiate)
        CHECK(q.command.total_size == s.command.total_size);
      CHECK(std::equal(q.command.payload.begin(), q.command.payload.end(),
                       s.command.payload.begin(), s.command.payload.end()));
    }
  }
}

TEST_CASE("Fuzz: random, truncated and mutated frames give a value or a named error",
          "[powerlink][codec][fuzz]") {
  std::mt19937 rng(987654);
  const auto samples = ds1928::powerlink::test::build_samples();
  std::vector<uint8_t> frame;
  std::size_t values = 0;
  std::size_t errors = 0;
  auto check_one = [&](std::span<const uint8_t> f) {
    auto r = parse_frame(f);
    if (r) {
      ++values;
      // Views stay inside the input.
      std::visit(
          [&](const auto& m) {
            using T = std::decay_t<decltype(m)>;
            if constexpr (std::is_same_v<T, PReq> || std::is_same_v<T, PRes>) {
              CHECK(m.payload.data() >= f.data());
              CHECK(m.payload.data() + m.payload.size() <= f.data() + f.size());
            }
          },
          r->message);
    } else {
      ++errors;
      CHECK(r.error().category() == frame_category());
      CHECK_FALSE(r.error().message().empty());
    }
  };
  for (int i = 0; i < 200000; ++i) {
    const auto& base = samples[rng() % samples.size()].bytes;
    frame = base;
    switch (rng() % 4) {
      case 0:  // truncate
        frame.resize(rng() % (base.size() + 1));
        break;
      case 1:  // flip bytes
        for (int k = 0, n = 1 + static_cast<int>(rng() % 4); k < n; ++k)
          frame[rng() % frame.size()] = static_cast<uint8_t>(rng());
        break;
      case 2:  // grow with garbage
        frame.resize(base.size() + rng() % 1600, static_cast<uint8_t>(rng()));
        break;
      default:  // random bytes with a POWERLINK header
        frame.resize(rng() % 1600);
        for (auto& b : frame) b = static_cast<uint8_t>(rng());
        if (frame.size() > 16) {
          frame[12] = 0x88;
          frame[13] = 0xAB;
          frame[14] = static_cast<uint8_t>(1 + rng() % 6);
        }
        break;
    }
    check_one(frame);
  }
  CHECK(values > 1000);
  CHECK(errors > 1000);
}
