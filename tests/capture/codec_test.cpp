// The capture codecs byte for byte: pcapng blocks (SHB, IDB with if_tsresol = 9, EPB with
// epb_flags, ISB with isb_ifdrop), the SocketCAN form of LINKTYPE_CAN_SOCKETCAN, candump log
// lines, base64. Then tshark (when installed) reads a file made of them.
#include <unistd.h>

#include <array>
#include <catch2/catch.hpp>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "capture/base64.hpp"
#include "capture/can_record.hpp"
#include "capture/pcapng.hpp"

using namespace ds1928::capture;
using Bytes = std::vector<uint8_t>;

namespace {
// Little-endian helpers for the expected layouts (the test targets are little-endian).
void le32(Bytes& b, uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<uint8_t>(v >> (8 * i)));
}
void le16(Bytes& b, uint16_t v) {
  b.push_back(static_cast<uint8_t>(v));
  b.push_back(static_cast<uint8_t>(v >> 8));
}
void le64(Bytes& b, uint64_t v) {
  le32(b, static_cast<uint32_t>(v));
  le32(b, static_cast<uint32_t>(v >> 32));
}
void text(Bytes& b, const char* s, std::size_t padded) {
  std::size_t i = 0;
  for (; s[i]; ++i) b.push_back(static_cast<uint8_t>(s[i]));
  for (; i < padded; ++i) b.push_back(0);
}
}  // namespace

TEST_CASE("pcapng section header block: magic, version 1.0, unknown length, shb_userappl") {
  Bytes out;
  append_section_header(out, "ds1928d");
  Bytes want;
  le32(want, 0x0A0D0D0A);
  le32(want, 44);
  le32(want, 0x1A2B3C4D);
  le16(want, 1);
  le16(want, 0);
  le64(want, 0xFFFFFFFFFFFFFFFFULL);
  le16(want, 4);  // shb_userappl
  le16(want, 7);
  text(want, "ds1928d", 8);
  le32(want, 0);  // opt_endofopt
  le32(want, 44);
  CHECK(out == want);
}

TEST_CASE("pcapng interface description block: link type, if_name, if_tsresol = 9 (ns)") {
  Bytes out;
  append_interface_description(out, {kLinkTypeCanSocketCan, 0, "can0", ""});
  Bytes want;
  le32(want, 1);
  le32(want, 40);
  le16(want, 227);
  le16(want, 0);
  le32(want, 0);  // snaplen: none
  le16(want, 2);  // if_name
  le16(want, 4);
  text(want, "can0", 4);
  le16(want, 9);  // if_tsresol
  le16(want, 1);
  want.insert(want.end(), {9, 0, 0, 0});
  le32(want, 0);
  le32(want, 40);
  CHECK(out == want);

  Bytes with_description;
  append_interface_description(with_description, {kLinkTypeEthernet, 0, "eth1", "MN port"});
  CHECK(with_description.size() == 40 + 12);  // if_description: 4 + "MN port" padded to 8
  CHECK(with_description[8] == 1);            // LINKTYPE_ETHERNET
}

TEST_CASE("pcapng enhanced packet block: 64-bit ns stamp split high/low, padding, epb_flags") {
  Bytes out;
  const Bytes frame{0xAA, 0xBB, 0xCC};
  append_enhanced_packet(out, 1, 0x0000000100000002ULL, frame, Direction::Inbound);
  Bytes want;
  le32(want, 6);
  le32(want, 48);
  le32(want, 1);  // interface
  le32(want, 1);  // timestamp high
  le32(want, 2);  // timestamp low
  le32(want, 3);  // captured
  le32(want, 3);  // original
  want.insert(want.end(), {0xAA, 0xBB, 0xCC, 0});
  le16(want, 2);  // epb_flags
  le16(want, 4);
  le32(want, 1);  // inbound
  le32(want, 0);
  le32(want, 48);
  CHECK(out == want);

  Bytes outbound;
  append_enhanced_packet(outbound, 0, 5, frame, Direction::Outbound);
  CHECK(outbound[36] == 2);  // direction bits: outbound
  Bytes unknown;
  append_enhanced_packet(unknown, 0, 5, frame, Direction::Unknown);
  CHECK(unknown.size() == 36);  // no options at all
}

TEST_CASE("pcapng interface statistics block: start/end time, ifrecv, ifdrop") {
  Bytes out;
  InterfaceStatistics s;
  s.interface_id = 2;
  s.time_ns = 0x0000000A0000000BULL;
  s.start_time_ns = 0x100000002ULL;
  s.end_time_ns = 0x300000004ULL;
  s.received = 1000;
  s.dropped = 7;
  append_interface_statistics(out, s);
  Bytes want;
  le32(want, 5);
  le32(want, 76);
  le32(want, 2);
  le32(want, 0xA);
  le32(want, 0xB);
  le16(want, 2);  // isb_starttime
  le16(want, 8);
  le32(want, 1);
  le32(want, 2);
  le16(want, 3);  // isb_endtime
  le16(want, 8);
  le32(want, 3);
  le32(want, 4);
  le16(want, 4);  // isb_ifrecv
  le16(want, 8);
  le64(want, 1000);
  le16(want, 5);  // isb_ifdrop
  le16(want, 8);
  le64(want, 7);
  le32(want, 0);
  le32(want, 76);
  CHECK(out == want);
}

TEST_CASE("SocketCAN form: id word in network byte order with EFF/RTR/ERR flags, data padded") {
  ds1928::canio::CanFrame f = ds1928::canio::make_standard_frame(0x181, Bytes{1, 2, 3});
  CHECK(socketcan_bytes(f) ==
        SocketCanBytes{0x00, 0x00, 0x01, 0x81, 3, 0, 0, 0, 1, 2, 3, 0, 0, 0, 0, 0});
  f.extended = true;
  f.id = 0x12345678 & 0x1FFFFFFF;
  CHECK(socketcan_bytes(f)[0] == 0x92);  // 0x80 (EFF) | 0x12
  CHECK(socketcan_bytes(f)[3] == 0x78);
  ds1928::canio::CanFrame r;
  r.id = 0x701;
  r.rtr = true;
  r.dlc = 1;
  r.data[0] = 0xEE;  // a remote frame carries no data
  CHECK(socketcan_bytes(r) ==
        SocketCanBytes{0x40, 0x00, 0x07, 0x01, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0});
  ds1928::canio::CanFrame e;
  e.error = true;
  e.id = 0x40;  // CAN_ERR_BUSOFF
  e.dlc = 0;
  e.data = {0, 0, 0, 0, 0, 0, 0, 0};
  const auto eb = socketcan_bytes(e);
  CHECK(eb[0] == 0x20);  // CAN_ERR_FLAG
  CHECK(eb[3] == 0x40);
  CHECK(eb[4] == 8);  // error frames: always 8 bytes
}

TEST_CASE("candump log lines as can-utils writes them") {
  const auto f = socketcan_bytes(ds1928::canio::make_standard_frame(0x80, Bytes{}));
  CHECK(candump_line(1'700'000'000'123'456'789, "can0", f) == "(1700000000.123456) can0 080#\n");
  const auto d = socketcan_bytes(ds1928::canio::make_standard_frame(0x1A5, Bytes{0xde, 0xad, 1}));
  CHECK(candump_line(5'000'001'000, "vcan1", d) == "(0000000005.000001) vcan1 1A5#DEAD01\n");
  ds1928::canio::CanFrame x;
  x.extended = true;
  x.id = 0x1ABCDE;
  x.dlc = 1;
  x.data[0] = 0x0F;
  CHECK(candump_line(0, "can0", socketcan_bytes(x)) == "(0000000000.000000) can0 001ABCDE#0F\n");
  ds1928::canio::CanFrame r;
  r.id = 0x123;
  r.rtr = true;
  CHECK(candump_line(0, "can0", socketcan_bytes(r)) == "(0000000000.000000) can0 123#R\n");
  ds1928::canio::CanFrame e;
  e.error = true;
  e.id = 0x4;
  e.data = {0, 0x10, 0, 0, 0, 0, 0, 0};
  CHECK(candump_line(0, "can0", socketcan_bytes(e)) ==
        "(0000000000.000000) can0 20000004#0010000000000000\n");
}

TEST_CASE("base64 round trip and refusal of non-canonical text") {
  CHECK(base64_encode(Bytes{}) == "");
  CHECK(base64_encode(Bytes{'f'}) == "Zg==");
  CHECK(base64_encode(Bytes{'f', 'o'}) == "Zm8=");
  CHECK(base64_encode(Bytes{'f', 'o', 'o', 'b', 'a', 'r'}) == "Zm9vYmFy");
  Bytes all(256);
  for (int i = 0; i < 256; ++i) all[i] = static_cast<uint8_t>(i);
  CHECK(base64_decode(base64_encode(all)) == all);
  CHECK(base64_decode("Zm8=") == Bytes{'f', 'o'});
  CHECK_FALSE(base64_decode("Zm8"));
  CHECK_FALSE(base64_decode("Z=8="));
  CHECK_FALSE(base64_decode("Zm8*"));
  CHECK_FALSE(base64_decode("Zg==Zg=="));
}

// A file of every block kind, Ethernet (a POWERLINK SoC) and SocketCAN interfaces: tshark must
// read it whole and decode it without a malformed packet.
TEST_CASE("tshark reads a produced pcapng file: POWERLINK and SocketCAN frames, statistics") {
  if (std::system("command -v tshark >/dev/null 2>&1") != 0) {
    WARN("tshark not installed: file check skipped");
    return;
  }
  Bytes file;
  append_section_header(file, "ds1928d test");
  append_interface_description(file, {kLinkTypeEthernet, 0, "veth0", "MN"});
  append_interface_description(file, {kLinkTypeCanSocketCan, 0, "can0", "cycle port"});
  // SoC: multicast 01:11:1E:00:00:01, EtherType 0x88AB, MessageType 1, dest 0xFF, source 240.
  Bytes soc{0x01, 0x11, 0x1E, 0, 0, 1, 0x02, 0, 0, 0, 0, 1, 0x88, 0xAB, 0x01, 0xFF, 0xF0};
  soc.resize(60, 0);
  const uint64_t t0 = 1'700'000'000'000'000'000ULL;
  append_enhanced_packet(file, 0, t0, soc, Direction::Outbound);
  append_enhanced_packet(
      file, 1, t0 + 1000,
      socketcan_bytes(ds1928::canio::make_standard_frame(0x181, Bytes{1, 2, 3, 4})),
      Direction::Inbound);
  InterfaceStatistics s;
  s.time_ns = s.end_time_ns = t0 + 2000;
  s.start_time_ns = t0;
  s.received = 1;
  s.dropped = 0;
  append_interface_statistics(file, s);
  s.interface_id = 1;
  s.received = 3;
  s.dropped = 2;
  append_interface_statistics(file, s);

  char path[] = "/tmp/capture_codec_XXXXXX";
  const int fd = mkstemp(path);
  REQUIRE(fd >= 0);
  REQUIRE(write(fd, file.data(), file.size()) == static_cast<ssize_t>(file.size()));
  close(fd);
  const std::string base = std::string("tshark -r ") + path;
  auto run = [](const std::string& cmd) {
    std::string out;
    FILE* p = popen(cmd.c_str(), "r");
    REQUIRE(p != nullptr);
    char buf[4096];
    while (std::size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    CHECK(pclose(p) == 0);
    return out;
  };
  const std::string fields = run(base +
                                 " -T fields -e frame.interface_id -e frame.packet_flags_direction "
                                 "-e frame.protocols -e frame.time_epoch 2>/dev/null");
  INFO(fields);
  CHECK(fields.find("0\t0x00000002\teth:ethertype:epl\t1700000000.000000000") != std::string::npos);
  CHECK(fields.find("1\t0x00000001\tcan") != std::string::npos);
  CHECK(run(base + " -Y '_ws.malformed || _ws.expert.severity >= error' 2>/dev/null").empty());
  // ... and the filter is one this tshark knows (an unknown field makes tshark fail).
  CHECK(std::system((base + " -Y '_ws.malformed || _ws.expert.severity >= error' >/dev/null 2>&1")
                        .c_str()) == 0);
  CHECK(std::system((base + " -Y '_ws.no_such_field' >/dev/null 2>&1").c_str()) != 0);
  unlink(path);
}
