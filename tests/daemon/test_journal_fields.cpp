// Journal fields of the daemon's event records, end to end: a real node reset (a PowerlinkBus
// and an in-memory CN that stops answering, as test_bus_watch) logged the daemon's way
// (log_bus_event through the asynchronous logger and the journald sink) reaches the journal
// socket as a native-protocol datagram with MESSAGE_ID, DS1928_NODE, DS1928_BUS, PRIORITY.
//
// The journal socket is the test's own: the test runs in a private mount namespace with a tmpfs
// on /run, where it binds /run/systemd/journal/socket, the path libsystemd's sd_journal_sendv()
// sends to. (Needs root for the namespace; the machine need not run systemd.)
#include <fcntl.h>
#include <sched.h>
#include <spdlog/sinks/ostream_sink.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <cstring>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "daemon.hpp"
#include "mn_rig.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "powerlink_service.hpp"
#include "service/journal.hpp"
#include "service/logging.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;

namespace {

using Record = std::map<std::string, std::string>;

// journald's native protocol: "KEY=value\n", or "KEY\n" + 64-bit LE length + value + "\n" for
// values with a line feed.
Record parse_native(std::string_view d) {
  Record r;
  while (!d.empty()) {
    const auto nl = d.find('\n');
    if (nl == std::string_view::npos) break;
    const std::string_view line = d.substr(0, nl);
    const auto eq = line.find('=');
    if (eq != std::string_view::npos) {
      r[std::string(line.substr(0, eq))] = std::string(line.substr(eq + 1));
      d.remove_prefix(nl + 1);
    } else {
      uint64_t len = 0;
      if (d.size() < nl + 1 + 8) break;
      std::memcpy(&len, d.data() + nl + 1, 8);
      r[std::string(line)] = std::string(d.substr(nl + 9, len));
      d.remove_prefix(std::min<std::size_t>(d.size(), nl + 9 + len + 1));
    }
  }
  return r;
}

// journalctl -o export style, for the documentation.
std::string export_text(const Record& r) {
  std::string s;
  for (const auto& [k, v] : r) s += k + "=" + v + "\n";
  return s;
}

class JournalSocket {
 public:
  JournalSocket() {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strcpy(a.sun_path, "/run/systemd/journal/socket");
    bound_ = fd_ >= 0 && ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    timeval tv{30, 0};  // a bound against a hang, never what is measured
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~JournalSocket() {
    if (fd_ >= 0) ::close(fd_);
  }
  [[nodiscard]] bool bound() const { return bound_; }
  // The next record; empty when none came within the bound.
  [[nodiscard]] Record next() {
    std::vector<char> buf(256 * 1024);
    const ssize_t n = ::recv(fd_, buf.data(), buf.size(), 0);
    if (n <= 0) return {};
    return parse_native(std::string_view(buf.data(), static_cast<std::size_t>(n)));
  }
  // Records until one with MESSAGE_ID `id` (the ones before are kept in `seen`).
  [[nodiscard]] Record until(std::string_view id, std::vector<Record>& seen) {
    for (;;) {
      Record r = next();
      if (r.empty()) return r;
      seen.push_back(r);
      if (r["MESSAGE_ID"] == id) return r;
    }
  }

 private:
  int fd_ = -1;
  bool bound_ = false;
};

// A private mount namespace with an empty tmpfs on /run. Before any thread exists (unshare of
// the mount namespace refuses a multithreaded caller).
bool private_run() {
  if (::unshare(CLONE_NEWNS) != 0) return false;
  if (::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0) return false;
  if (::mount("tmpfs", "/run", "tmpfs", 0, "mode=0755") != 0) return false;
  return ::mkdir("/run/systemd", 0755) == 0 && ::mkdir("/run/systemd/journal", 0755) == 0;
}

}  // namespace

TEST_CASE("A node reset reaches the journal with MESSAGE_ID, DS1928_NODE and DS1928_BUS",
          "[daemon][log][journal]") {
  if (::geteuid() != 0) {
    WARN("needs root (a private mount namespace for the test's journal socket): not run");
    return;
  }
  REQUIRE(private_run());
  JournalSocket journal;
  REQUIRE(journal.bound());
  control::setup_logging(spdlog::level::info, control::LogSink::Journald, "ds1928d");

  powerlink::test::Rig rig({1}, 1);
  BusWatch watch;
  PowerlinkService service(*rig.bus);
  (void)watch.poll(service);
  REQUIRE(rig.run_until([&] { return rig.bus->state() == BusState::Operational; }));
  for (const BusEvent& e : watch.poll(service)) log_bus_event(e, service.driver().name());
  rig.cns[0]->drop_pres = true;  // two lost PRes in a row: the MN resets the node
  rig.step();
  rig.step();
  rig.cns[0]->drop_pres = false;
  for (const BusEvent& e : watch.poll(service)) log_bus_event(e, service.driver().name());

  std::vector<Record> seen;
  Record reset = journal.until(control::message_id(control::LogEvent::NodeReset), seen);
  control::shutdown_logging();
  std::string all;
  for (const Record& r : seen) all += export_text(r) + "\n";
  INFO(all);
  // The export form of what the test saw, for docs/operations.md.
  std::fprintf(stderr, "%s", all.c_str());
  REQUIRE_FALSE(reset.empty());
  CHECK(reset["MESSAGE"] ==
        "powerlink node 1: reset by the MN (loss of PRes threshold reached; resets 1, PRes "
        "losses 2)");
  CHECK(reset["MESSAGE_ID"] == "1642b70e82c14d7b8287c491010440b9");
  CHECK(reset["DS1928_NODE"] == "1");
  CHECK(reset["DS1928_BUS"] == "powerlink");
  CHECK(reset["DS1928_REASON"] == "loss of PRes threshold reached");
  CHECK(reset["PRIORITY"] == "4");
  CHECK(reset["SYSLOG_IDENTIFIER"] == "ds1928d");
  CHECK(reset.count("DS1928_AXIS") == 0);

  // Before it: the boot, with its own id and the node; the bus state changes with the bus only.
  REQUIRE(seen.size() >= 3);
  const auto find = [&](control::LogEvent e) {
    for (const Record& r : seen)
      if (r.at("MESSAGE_ID") == control::message_id(e)) return r;
    return Record{};
  };
  Record boot = find(control::LogEvent::NodeOperational);
  CHECK(boot["MESSAGE"] == "powerlink node 1: operational (boot 1)");
  CHECK(boot["DS1928_NODE"] == "1");
  CHECK(boot["PRIORITY"] == "6");
  Record state = find(control::LogEvent::BusState);
  CHECK(state["DS1928_BUS"] == "powerlink");
  CHECK(state.count("DS1928_NODE") == 0);
}

TEST_CASE("Without journald the text of an event record is unchanged", "[daemon][log][journal]") {
  std::ostringstream text;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(text);
  sink->set_pattern("%v");
  auto logger = std::make_shared<spdlog::logger>("journal-test", sink);
  spdlog::set_default_logger(logger);
  control::set_structured_logging(false);
  log_bus_event(BusEvent(true, "powerlink node 7: reset by the MN (x)",
                         control::LogEvent::NodeReset, 7, -1, "x"),
                "powerlink");
  CHECK(text.str() == "powerlink node 7: reset by the MN (x)\n");

  // With journald, the same call frames the fields in front of the text for the sink.
  text.str("");
  control::set_structured_logging(true);
  log_bus_event(BusEvent(true, "t", control::LogEvent::NodeReset, 7, 2, "x"), "powerlink");
  control::set_structured_logging(false);
  std::string framed = text.str();
  REQUIRE(framed.size() > 1);
  framed.pop_back();  // the pattern's line feed
  const control::SplitRecord r = control::split_record(framed);
  CHECK(r.text == "t");
  REQUIRE(r.field_count == 5);
  CHECK(r.fields[0] == "MESSAGE_ID=1642b70e82c14d7b8287c491010440b9");
  CHECK(r.fields[1] == "DS1928_NODE=7");
  CHECK(r.fields[2] == "DS1928_AXIS=2");
  CHECK(r.fields[3] == "DS1928_BUS=powerlink");
  CHECK(r.fields[4] == "DS1928_REASON=x");
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("", spdlog::sinks_init_list{}));
}

TEST_CASE("Every event kind has its own 128-bit MESSAGE_ID", "[daemon][log][journal]") {
  std::set<std::string_view> ids;
  for (std::size_t i = 1; i < control::kLogEventCount; ++i) {
    const auto id = control::message_id(static_cast<control::LogEvent>(i));
    INFO(control::event_name(static_cast<control::LogEvent>(i)));
    CHECK(id.size() == 32);
    CHECK(id.find_first_not_of("0123456789abcdef") == std::string_view::npos);
    ids.insert(id);
  }
  CHECK(ids.size() == control::kLogEventCount - 1);
  CHECK(control::message_id(control::LogEvent::None).empty());
}
