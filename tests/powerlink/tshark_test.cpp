// Proof that Wireshark's POWERLINK dissector decodes the frames the codec builds.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <fstream>
#include <string>

#include "frame_samples.hpp"
#include "pcap_util.hpp"

namespace {

using ds1928::powerlink::test::run_command;
using ds1928::powerlink::test::write_pcap;

std::size_t count(const std::string& hay, const std::string& needle) {
  std::size_t n = 0;
  for (auto pos = hay.find(needle); pos != std::string::npos; pos = hay.find(needle, pos + 1)) ++n;
  return n;
}

}  // namespace

TEST_CASE("Wireshark decodes every frame type the codec builds", "[powerlink][codec][tshark]") {
  if (access("/usr/bin/tshark", X_OK) != 0) {
    WARN("tshark not installed: Wireshark decoding check skipped");
    return;
  }
  const auto samples = ds1928::powerlink::test::build_samples();
  REQUIRE(samples.size() == 15);
  const std::string path = DS1928_TEST_TMPDIR "/powerlink_samples.pcap";
  std::vector<std::vector<uint8_t>> frames;
  for (const auto& sample : samples) frames.push_back(sample.bytes);
  write_pcap(path, frames);
  const std::string verbose = run_command("tshark -n -r " + path + " -V 2>&1");
  INFO(verbose);
  CHECK(verbose.find("Malformed") == std::string::npos);
  CHECK(verbose.find("Expert Info (Error") == std::string::npos);
  CHECK(verbose.find("Expert Info (Warning") == std::string::npos);
  // Every frame went to the POWERLINK dissector.
  const std::string lines =
      run_command("tshark -n -r " + path + " -T fields -e epl.mtyp 2>/dev/null");
  INFO(lines);
  CHECK(count(lines, "\n") == samples.size());
  CHECK(lines.find("\n\n") == std::string::npos);
  CHECK(lines.rfind("\n", 0) != 0);
  const std::string summary = run_command("tshark -n -r " + path + " 2>/dev/null");
  INFO(summary);
  for (const char* what :
       {"SoC", "PReq [  36]", "PRes [  46]", "(STATUS_REQUEST)->  1", "(IDENT_REQUEST)->  1",
        "(UNSPEC_INVITE)->240", "IDENT_RESPONSE", "STATUS_RESPONSE", "NMTStartNode", "NMT_REQUEST",
        "(InitReq)", "WriteByIndex[5]: (0x2001/1)", "ReadByIndex[4]: (0x2001/7)",
        "Abort:0x06020000"})
    CHECK(summary.find(what) != std::string::npos);
  const std::string expert = run_command("tshark -n -r " + path + " -q -z expert,warn 2>&1");
  INFO(expert);
  CHECK(expert.find("Malformed") == std::string::npos);
}

TEST_CASE("Wireshark decodes unpadded 54-byte frames the codec accepts",
          "[powerlink][codec][tshark]") {
  if (access("/usr/bin/tshark", X_OK) != 0) {
    WARN("tshark not installed: Wireshark decoding check skipped");
    return;
  }
  const auto samples = ds1928::powerlink::test::build_samples();
  // SoC, SoA StatusRequest, SoA IdentRequest, NMTCommand, SDO sequence init cut to 54 bytes, as
  // a software sender on a veth/TAP link sends them.
  std::vector<std::vector<uint8_t>> frames;
  for (std::size_t i : {0, 3, 4, 8, 10}) {
    auto f = samples.at(i).bytes;
    f.resize(54);
    REQUIRE(ds1928::powerlink::parse_frame(f));
    frames.push_back(f);
  }
  const std::string path = DS1928_TEST_TMPDIR "/powerlink_short.pcap";
  write_pcap(path, frames);
  const std::string verbose = run_command("tshark -n -r " + path + " -V 2>&1");
  INFO(verbose);
  CHECK(verbose.find("Malformed") == std::string::npos);
  CHECK(verbose.find("Expert Info (Error") == std::string::npos);
  CHECK(verbose.find("Expert Info (Warning") == std::string::npos);
  const std::string lines =
      run_command("tshark -n -r " + path + " -T fields -e epl.mtyp 2>/dev/null");
  INFO(lines);
  CHECK(count(lines, "\n") == frames.size());
  CHECK(lines.find("\n\n") == std::string::npos);
}
