// Proof that Wireshark's POWERLINK dissector decodes the frames the codec builds.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <fstream>
#include <string>

#include "frame_samples.hpp"

namespace {

void put32(std::ofstream& f, uint32_t v) {
  f.write(reinterpret_cast<const char*>(&v), 4);
}
void put16(std::ofstream& f, uint16_t v) {
  f.write(reinterpret_cast<const char*>(&v), 2);
}

void write_pcap(const std::string& path,
                const std::vector<ds1928::powerlink::test::Sample>& frames) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  put32(f, 0xA1B2C3D4);  // microsecond pcap, host byte order
  put16(f, 2);
  put16(f, 4);
  put32(f, 0);
  put32(f, 0);
  put32(f, 65535);
  put32(f, 1);  // LINKTYPE_ETHERNET
  uint32_t t = 0;
  for (const auto& s : frames) {
    put32(f, 1700000000);
    put32(f, t += 10);
    put32(f, static_cast<uint32_t>(s.bytes.size()));
    put32(f, static_cast<uint32_t>(s.bytes.size()));
    f.write(reinterpret_cast<const char*>(s.bytes.data()),
            static_cast<std::streamsize>(s.bytes.size()));
  }
}

std::string run(const std::string& cmd) {
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  pclose(p);
  return out;
}

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
  const std::string path = std::string(DS1928_TEST_TMPDIR) + "/powerlink_samples.pcap";
  write_pcap(path, samples);
  const std::string verbose = run("tshark -n -r " + path + " -V 2>&1");
  INFO(verbose);
  CHECK(verbose.find("Malformed") == std::string::npos);
  CHECK(verbose.find("Expert Info (Error") == std::string::npos);
  CHECK(verbose.find("Expert Info (Warning") == std::string::npos);
  // Every frame went to the POWERLINK dissector.
  const std::string lines = run("tshark -n -r " + path + " -T fields -e epl.mtyp 2>/dev/null");
  INFO(lines);
  CHECK(count(lines, "\n") == samples.size());
  CHECK(lines.find("\n\n") == std::string::npos);
  CHECK(lines.rfind("\n", 0) != 0);
  const std::string summary = run("tshark -n -r " + path + " 2>/dev/null");
  INFO(summary);
  for (const char* what :
       {"SoC", "PReq [  36]", "PRes [  46]", "(STATUS_REQUEST)->  1", "(IDENT_REQUEST)->  1",
        "(UNSPEC_INVITE)->240", "IDENT_RESPONSE", "STATUS_RESPONSE", "NMTStartNode", "NMT_REQUEST",
        "(InitReq)", "WriteByIndex[5]: (0x2001/1)", "ReadByIndex[4]: (0x2001/7)",
        "Abort:0x06020000"})
    CHECK(summary.find(what) != std::string::npos);
  const std::string expert = run("tshark -n -r " + path + " -q -z expert,warn 2>&1");
  INFO(expert);
  CHECK(expert.find("Malformed") == std::string::npos);
}
