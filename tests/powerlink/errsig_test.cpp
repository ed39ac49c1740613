// Error signalling (EPSG DS 301): the frame bytes that carry it (ER/EA in the SoA, EA in the PReq,
// EN/EC, the static error bit field and the entries in the StatusResponse), Wireshark's reading
// of them, and both roles' state machines driven against each other.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <string>
#include <vector>

#include "frame_samples.hpp"
#include "pcap_util.hpp"
#include "powerlink/error_signalling.hpp"
#include "powerlink/frames.hpp"

using namespace ds1928::powerlink;
using ds1928::powerlink::test::kCnMac;
using ds1928::powerlink::test::kMnMac;

namespace {

ErrorEntry sample_entry() {
  ErrorEntry e;
  e.type = entry_type::kEmergency | entry_type::kModeOccurred | entry_type::kProfileVendor;
  e.code = 0x1928;
  e.timestamp = (static_cast<uint64_t>(500'000'000) << 32) | 12;  // 12.5 s
  e.additional = {1, 2, 3, 4, 5, 6, 7, 8};
  return e;
}

std::vector<uint8_t> status_frame(bool en, bool ec, std::span<const ErrorEntry> entries,
                                  uint64_t bits) {
  std::array<uint8_t, kMaxFrameSize> buf{};
  StatusResponse st;
  st.exception_new = en;
  st.exception_clear = ec;
  st.nmt_state = NmtState::kOperational;
  st.static_error_bits = bits;
  auto len = build_status_response(buf, asnd_header(kCnMac, 1, kNodeMn), st, entries);
  REQUIRE(len);
  return {buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(*len)};
}

}  // namespace

TEST_CASE("Error signalling flags and entries sit where DS 301 puts them", "[powerlink][errsig]") {
  const ErrorEntry e = sample_entry();
  const auto f = status_frame(true, true, {&e, 1}, 0x01);
  REQUIRE(f.size() == 72);  // 32 + one entry + the terminating entry
  CHECK(f[17] == 0x02);     // StatusResponse
  CHECK(f[18] == 0x18);     // EN 0x10 | EC 0x08
  CHECK(f[20] == 0xFD);
  CHECK(f[24] == 0x01);  // error register (0x1001) in byte 0 of the static bit field
  CHECK(std::all_of(f.begin() + 25, f.begin() + 32, [](uint8_t b) { return b == 0; }));
  const std::array<uint8_t, 20> entry{0x01, 0x70, 0x28, 0x19, 12, 0, 0, 0, 0x00, 0x65,
                                      0xCD, 0x1D, 1,    2,    3,  4, 5, 6, 7,    8};
  CHECK(std::equal(entry.begin(), entry.end(), f.begin() + 32));
  CHECK(std::all_of(f.begin() + 52, f.end(), [](uint8_t b) { return b == 0; }));
  auto parsed = parse_asnd(f);
  REQUIRE(parsed);
  const auto& st = std::get<StatusResponse>(parsed->body);
  CHECK(st.exception_new);
  CHECK(st.exception_clear);
  CHECK(st.static_error_bits == 0x01);
  REQUIRE(st.entry_count() == 1);
  CHECK(st.entry(0) == e);

  std::array<uint8_t, kMaxFrameSize> buf{};
  SoA soa;
  soa.exception_reset = true;
  soa.exception_acknowledge = true;
  soa.service = RequestedService::kStatusRequest;
  soa.target = 1;
  REQUIRE(build_soa(buf, soa_header(kMnMac), soa));
  CHECK(buf[18] == 0x06);  // EA 0x04 | ER 0x02
  PReq preq;
  preq.exception_acknowledge = true;
  REQUIRE(build_preq(buf, preq_header(kMnMac, kCnMac, 1), preq));
  CHECK(buf[18] == 0x04);
  CHECK(describe(e).find("0x1928 (vendor, occurred, emergency) at 12.500000000 s") == 0);
}

TEST_CASE("Wireshark reads the error signalling fields as the codec writes them",
          "[powerlink][errsig][tshark]") {
  if (access("/usr/bin/tshark", X_OK) != 0) {
    WARN("tshark not installed: Wireshark decoding check skipped");
    return;
  }
  const ErrorEntry e = sample_entry();
  std::vector<std::vector<uint8_t>> frames;
  frames.push_back(status_frame(true, false, {&e, 1}, 0x01));
  std::array<uint8_t, kMaxFrameSize> buf{};
  SoA soa;
  soa.exception_reset = true;
  soa.service = RequestedService::kStatusRequest;
  soa.target = 1;
  auto len = build_soa(buf, soa_header(kMnMac), soa);
  REQUIRE(len);
  frames.emplace_back(buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(*len));
  const std::string path = DS1928_TEST_TMPDIR "/powerlink_errsig.pcap";
  ds1928::powerlink::test::write_pcap(path, frames);
  using ds1928::powerlink::test::run_command;
  const std::string sres = run_command(
      "tshark -n -r " + path +
      " -Y 'epl.asnd.svid == 2' -T fields -E separator=, -e epl.asnd.sres.en -e "
      "epl.asnd.sres.ec -e epl.asnd.sres.el.entry.code -e epl.asnd.sres.el.entry.type.profile "
      "-e epl.asnd.sres.el.entry.type.mode 2>/dev/null");
  INFO(sres);
  // EN 1, EC 0, entry codes 0x1928 (6440) and the terminator's 0, profiles vendor (1) and 0,
  // modes occurred (3) and 0.
  CHECK((sres == "1,0,6440,0,1,0,3,0\n" || sres == "True,False,6440,0,1,0,3,0\n"));
  const std::string soa_er =
      run_command("tshark -n -r " + path + " -Y 'epl.soa' -T fields -e epl.soa.er 2>/dev/null");
  INFO(soa_er);
  CHECK((soa_er == "1\n" || soa_er == "True\n"));
  const std::string verbose = run_command("tshark -n -r " + path + " -V 2>&1");
  INFO(verbose);
  CHECK(verbose.find("Malformed") == std::string::npos);
  CHECK(verbose.find("Expert Info (Warning") == std::string::npos);
  CHECK(verbose.find("Expert Info (Error") == std::string::npos);
}

TEST_CASE("CN: EC follows the ER it is asked with, and is set after a reset",
          "[powerlink][errsig]") {
  CnErrorSignalling cn;
  CHECK(cn.exception_clear());  // after power-up: the MN sees the reboot
  CHECK_FALSE(cn.exception_new());
  cn.on_status_request(true, false);
  CHECK(cn.exception_clear());
  cn.on_status_request(true, false);
  CHECK(cn.exception_clear());
  cn.on_status_request(false, false);
  CHECK_FALSE(cn.exception_clear());
  cn.on_status_request(false, false);
  CHECK_FALSE(cn.exception_clear());
  // The MN starts again (it restarted, or lost the node): ER=1 again.
  cn.on_status_request(true, false);
  CHECK(cn.exception_clear());
  cn.on_status_request(false, false);
  CHECK_FALSE(cn.exception_clear());
  cn.reset();
  CHECK(cn.exception_clear());
}

TEST_CASE("CN: EN toggles once per acknowledged batch, entries stay until EA",
          "[powerlink][errsig]") {
  CnErrorSignalling cn;
  cn.on_status_request(true, false);
  cn.on_status_request(false, false);
  ErrorEntry a = sample_entry();
  a.code = 0xA;
  ErrorEntry b = sample_entry();
  b.code = 0xB;
  cn.queue(a);
  CHECK(cn.exception_new());
  CHECK(cn.static_error_bits() == kErrorRegisterGeneric);
  cn.queue(b);
  CHECK(cn.exception_new());  // no second toggle before EA
  cn.on_preq(false);          // old EA: nothing acknowledged
  REQUIRE(cn.entries().size() == 2);
  cn.status_sent();
  ErrorEntry c = sample_entry();
  c.code = 0xC;
  cn.queue(c);       // after the StatusResponse went out
  cn.on_preq(true);  // EA = EN: a and b delivered; c toggles EN again
  REQUIRE(cn.entries().size() == 1);
  CHECK(cn.entries()[0].code == 0xC);
  CHECK_FALSE(cn.exception_new());
  cn.status_sent();
  cn.on_preq(false);
  CHECK(cn.entries().empty());
  CHECK(cn.static_error_bits() == 0);
  CHECK_FALSE(cn.exception_new());
}

TEST_CASE("CN: the emergency queue is bounded (oldest dropped)", "[powerlink][errsig]") {
  CnErrorSignalling cn;
  for (uint16_t i = 0; i < CnErrorSignalling::kQueueDepth + 3; ++i) {
    ErrorEntry e = sample_entry();
    e.code = i;
    cn.queue(e);
  }
  REQUIRE(cn.entries().size() == CnErrorSignalling::kQueueDepth);
  CHECK(cn.entries()[0].code == 3);
  CHECK(cn.dropped() == 3);
  CHECK((cn.entries()[0].type & entry_type::kEmergency) != 0);
}

TEST_CASE("MN: ER until EC=1, then ER=0 until EC=0, a CN that lags a request is fine",
          "[powerlink][errsig]") {
  MnErrorSignalling mn;
  CHECK(mn.status_request_due());
  CHECK(mn.exception_reset());
  mn.on_status_request_sent();
  CHECK_FALSE(mn.on_status_response(false, false));  // not yet
  CHECK(mn.state() == ErrSigState::kInitWaitEc1);
  mn.on_status_request_sent();
  CHECK_FALSE(mn.on_status_response(false, true));
  CHECK(mn.state() == ErrSigState::kInitWaitEc0);
  CHECK_FALSE(mn.exception_reset());
  mn.on_status_request_sent();
  CHECK_FALSE(mn.on_status_response(false, true));  // answer built before it saw ER=0
  CHECK(mn.state() == ErrSigState::kInitWaitEc0);
  mn.on_status_request_sent();
  CHECK_FALSE(mn.on_status_response(false, false));
  CHECK(mn.state() == ErrSigState::kReady);
  CHECK_FALSE(mn.status_request_due());
  CHECK(mn.handshakes() == 1);
  // EN toggles: fetch, then EA follows EN.
  mn.on_exception_new(false);
  CHECK_FALSE(mn.status_request_due());
  mn.on_exception_new(true);
  CHECK(mn.status_request_due());
  CHECK(mn.on_status_response(true, false));
  CHECK(mn.exception_acknowledge());
  CHECK_FALSE(mn.status_request_due());
  CHECK_FALSE(mn.on_status_response(true, false));  // same EN: nothing new
  // EC=1 while ready: the CN was reset; start over.
  CHECK_FALSE(mn.on_status_response(true, true));
  CHECK(mn.state() == ErrSigState::kInitWaitEc1);
  CHECK_FALSE(mn.exception_acknowledge());
}

TEST_CASE("MN: a CN that never answers EC=1 is given up on after the bound",
          "[powerlink][errsig]") {
  MnErrorSignalling mn;
  for (uint32_t i = 0; i < MnErrorSignalling::kMaxAttempts; ++i) {
    mn.on_status_request_sent();
    (void)mn.on_status_response(false, false);
  }
  CHECK(mn.state() == ErrSigState::kInitWaitEc1);
  mn.on_status_request_sent();
  CHECK(mn.state() == ErrSigState::kGaveUp);
  CHECK(mn.gave_up() == 1);
  CHECK_FALSE(mn.status_request_due());
  // Its EN toggles are still fetched.
  mn.on_exception_new(true);
  CHECK(mn.status_request_due());
  CHECK(mn.on_status_response(true, false));
  mn.restart();
  CHECK(mn.state() == ErrSigState::kInitWaitEc1);
  CHECK(mn.gave_up() == 1);
}

TEST_CASE("MN and CN state machines deliver every entry exactly once", "[powerlink][errsig]") {
  CnErrorSignalling cn;
  MnErrorSignalling mn;
  std::vector<uint16_t> delivered;
  uint16_t next = 1;
  // One "cycle": PReq with EA, PRes with EN, and a StatusRequest when the MN wants one.
  for (int cycle = 0; cycle < 200; ++cycle) {
    if (cycle % 7 == 3 && next <= 20) {
      ErrorEntry e = sample_entry();
      e.code = next++;
      cn.queue(e);
    }
    cn.on_preq(mn.exception_acknowledge());
    mn.on_exception_new(cn.exception_new());
    if (mn.status_request_due()) {
      const bool er = mn.exception_reset();
      const bool ea = mn.exception_acknowledge();
      mn.on_status_request_sent();
      cn.on_status_request(er, ea);
      const auto entries = cn.entries();
      std::vector<ErrorEntry> copy(entries.begin(), entries.end());
      const bool en = cn.exception_new();
      const bool ec = cn.exception_clear();
      cn.status_sent();
      if (mn.on_status_response(en, ec))
        for (const ErrorEntry& e : copy) delivered.push_back(e.code);
    }
  }
  CHECK(mn.state() == ErrSigState::kReady);
  std::vector<uint16_t> expected;
  for (uint16_t i = 1; i <= 20; ++i) expected.push_back(i);
  CHECK(delivered == expected);
  CHECK(cn.entries().empty());
}
