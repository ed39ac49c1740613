// The control socket with a real Unix socket: framing, errors, limits, peers, asynchronous
// replies, disconnects.
#include <sys/stat.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <mutex>
#include <vector>

#include "control_test_util.hpp"
#include "support/wait.hpp"

using namespace ds1928;
using namespace ds1928::control;
using namespace ds1928::control::test;
using json = nlohmann::json;

namespace {

SocketConfig config_for(const char* what) {
  SocketConfig c;
  c.path = temp_socket_path(what);
  c.mode = 0660;
  c.max_clients = 8;
  c.max_request_bytes = 256;
  c.idle_timeout_ms = 5000;
  return c;
}

// "echo": replies with its peer and arguments; "axis": takes a typed argument.
void add_test_commands(Server& server) {
  server.add_command("echo", [](const Request& req, Reply reply) {
    reply.ok({{"pid", req.peer().pid},
              {"uid", req.peer().uid},
              {"gid", req.peer().gid},
              {"text", req.opt_string("text").value_or("")}});
  });
  server.add_command("axis", [](const Request& req, Reply reply) {
    const auto axis = req.get_uint("axis", 3);
    const auto bits = req.opt_uint("bits", 0xff).value_or(0);
    const bool verbose = req.opt_bool("verbose").value_or(false);
    reply.ok({{"axis", axis}, {"bits", bits}, {"verbose", verbose}});
  });
}

}  // namespace

TEST_CASE("a command gets its peer's credentials and its reply echoes the id") {
  ServerThread t(config_for("basic"));
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  struct stat st {};
  REQUIRE(stat(t.server().path().c_str(), &st) == 0);
  CHECK(S_ISSOCK(st.st_mode));
  CHECK((st.st_mode & 0777) == 0660);

  LineClient c(t.server().path());
  REQUIRE(c.connected());
  const json r = c.request({{"cmd", "echo"}, {"text", "hi"}, {"id", 42}});
  CHECK(r["ok"] == true);
  CHECK(r["id"] == 42);
  CHECK(r["text"] == "hi");
  CHECK(r["pid"] == getpid());
  CHECK(r["uid"] == getuid());
  CHECK(r["gid"] == getgid());
  const json r2 = c.request({{"cmd", "echo"}, {"id", "abc"}});
  CHECK(r2["id"] == "abc");
  const json r3 = c.request({{"cmd", "echo"}});
  CHECK_FALSE(r3.contains("id"));
}

TEST_CASE("malformed JSON, non-objects and a missing cmd get precise errors, the line survives") {
  ServerThread t(config_for("badjson"));
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());

  c.send_raw("{\"cmd\": \"echo\",\n");
  json r = c.reply();
  CHECK(r["ok"] == false);
  CHECK(error_code_of(r) == "bad_json");
  CHECK_THAT(error_message_of(r), Catch::Contains("column"));

  c.send_raw("[1,2]\n");
  r = c.reply();
  CHECK(error_code_of(r) == "bad_json");
  CHECK_THAT(error_message_of(r), Catch::Contains("array"));

  r = c.request({{"text", "no command"}, {"id", 7}});
  CHECK(error_code_of(r) == "bad_argument");
  CHECK_THAT(error_message_of(r), Catch::Contains("'cmd'"));
  CHECK(r["id"] == 7);
  r = c.request({{"cmd", 12}});
  CHECK(error_code_of(r) == "bad_argument");
  CHECK_THAT(error_message_of(r), Catch::Contains("expected string"));

  c.send_raw("\n\r\n");  // empty lines are skipped, not answered
  r = c.request({{"cmd", "echo"}, {"text", "still here"}});
  CHECK(r["ok"] == true);
  CHECK(r["text"] == "still here");
}

TEST_CASE("unknown commands are named in the error") {
  ServerThread t(config_for("unknown"));
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());
  const json r = c.request({{"cmd", "reboot"}, {"id", 1}});
  CHECK(r["ok"] == false);
  CHECK(error_code_of(r) == "unknown_command");
  CHECK_THAT(error_message_of(r), Catch::Contains("'reboot'") && Catch::Contains("echo"));
  CHECK(r["id"] == 1);
}

TEST_CASE("wrong argument types and ranges name the argument and the expected type") {
  ServerThread t(config_for("args"));
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());

  json r = c.request({{"cmd", "axis"}, {"axis", 2}, {"bits", 255}, {"verbose", true}});
  CHECK(r["ok"] == true);
  CHECK(r["axis"] == 2);
  CHECK(r["bits"] == 255);
  CHECK(r["verbose"] == true);

  struct Case {
    json body;
    const char* needle;
  };
  const std::vector<Case> cases = {
      {{{"cmd", "axis"}}, "'axis' (unsigned integer) is required"},
      {{{"cmd", "axis"}, {"axis", "1"}}, "'axis': expected unsigned integer 0..3, got string"},
      {{{"cmd", "axis"}, {"axis", -1}}, "'axis': expected unsigned integer 0..3, got -1"},
      {{{"cmd", "axis"}, {"axis", 4}}, "'axis': expected unsigned integer 0..3, got 4"},
      {{{"cmd", "axis"}, {"axis", 1.5}}, "'axis': expected unsigned integer 0..3, got number"},
      {{{"cmd", "axis"}, {"axis", 0}, {"bits", 256}}, "'bits': expected unsigned integer 0..255"},
      {{{"cmd", "axis"}, {"axis", 0}, {"verbose", 1}}, "'verbose': expected boolean"},
      {{{"cmd", "echo"}, {"text", json::array()}}, "'text': expected string, got array"},
  };
  for (const auto& k : cases) {
    r = c.request(k.body);
    INFO(k.body.dump() << " -> " << r.dump());
    CHECK(r["ok"] == false);
    CHECK(error_code_of(r) == "bad_argument");
    CHECK_THAT(error_message_of(r), Catch::Contains(k.needle));
  }
}

TEST_CASE("oversized requests: a long line is refused, an endless one closes the connection") {
  ServerThread t(config_for("large"));  // 256-byte requests
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());
  const std::string big = json{{"cmd", "echo"}, {"text", std::string(300, 'x')}}.dump();
  // Sent in one piece with its newline: refused, and the next request is still served.
  c.send_raw(big + "\n" + json{{"cmd", "echo"}, {"text", "ok"}}.dump() + "\n");
  json r = c.reply();
  CHECK(error_code_of(r) == "request_too_large");
  CHECK_THAT(error_message_of(r), Catch::Contains("256"));
  r = c.reply();
  CHECK(r["ok"] == true);
  CHECK(r["text"] == "ok");

  // No newline in sight after the limit: the server answers and hangs up.
  LineClient d(t.server().path());
  d.send_raw(std::string(1000, 'y'));
  r = d.reply();
  CHECK(error_code_of(r) == "request_too_large");
  CHECK(d.at_eof());
  CHECK(t.wait_clients(1));  // only c is left
}

TEST_CASE("100 concurrent clients are all served") {
  SocketConfig cfg = config_for("many");
  cfg.max_clients = 128;
  ServerThread t(cfg);
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());

  std::vector<std::unique_ptr<LineClient>> clients;
  for (int i = 0; i < 100; ++i) clients.push_back(std::make_unique<LineClient>(t.server().path()));
  for (auto& c : clients) REQUIRE(c->connected());
  REQUIRE(t.wait_clients(100));
  // All requests are in flight before the first reply is read.
  for (int i = 0; i < 100; ++i)
    clients[i]->send_raw(json{{"cmd", "echo"}, {"text", std::to_string(i)}, {"id", i}}.dump() +
                         "\n");
  std::atomic<int> good{0};
  std::vector<std::thread> readers;
  for (int part = 0; part < 4; ++part) {
    readers.emplace_back([&, part] {
      for (int i = part; i < 100; i += 4) {
        const json r = clients[i]->reply();
        if (r.is_object() && r["ok"] == true && r["id"] == i && r["text"] == std::to_string(i))
          ++good;
      }
    });
  }
  for (auto& th : readers) th.join();
  CHECK(good == 100);
  clients.clear();
  CHECK(t.wait_clients(0));
}

TEST_CASE("clients beyond the limit get too_many_clients and are dropped") {
  SocketConfig cfg = config_for("limit");
  cfg.max_clients = 2;
  ServerThread t(cfg);
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient a(t.server().path()), b(t.server().path());
  REQUIRE(t.wait_clients(2));
  LineClient c(t.server().path());
  const json r = c.reply();
  CHECK(error_code_of(r) == "too_many_clients");
  CHECK(c.at_eof());
  CHECK(a.request({{"cmd", "echo"}})["ok"] == true);
  a.close();
  REQUIRE(t.wait_clients(1));
  LineClient d(t.server().path());
  CHECK(d.request({{"cmd", "echo"}})["ok"] == true);
}

TEST_CASE("an idle client gets idle_timeout and is closed") {
  SocketConfig cfg = config_for("idle");
  cfg.idle_timeout_ms = 150;
  ServerThread t(cfg);
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());
  // Taken before the request: the server re-arms the timer after it, so the idle reply cannot
  // come earlier than 150 ms after this, however late this thread runs.
  const auto t0 = std::chrono::steady_clock::now();
  CHECK(c.request({{"cmd", "echo"}})["ok"] == true);  // activity re-arms the timer
  const json r = c.reply();
  const auto waited = std::chrono::steady_clock::now() - t0;
  CHECK(error_code_of(r) == "idle_timeout");
  CHECK(waited >= std::chrono::milliseconds(150));
  CHECK(c.at_eof());
  CHECK(t.wait_clients(0));
}

TEST_CASE("a client that disconnects mid-request is dropped without harm") {
  ServerThread t(config_for("midreq"));
  std::atomic<int> calls{0};
  t.server().add_command("echo", [&](const Request&, Reply reply) {
    ++calls;
    reply.ok();
  });
  REQUIRE_FALSE(t.start());
  {
    LineClient c(t.server().path());
    REQUIRE(t.wait_clients(1));
    c.send_raw("{\"cmd\":\"ec");  // half a request, then gone
  }
  CHECK(t.wait_clients(0));
  CHECK(calls == 0);
  LineClient d(t.server().path());
  CHECK(d.request({{"cmd", "echo"}})["ok"] == true);
  CHECK(calls == 1);
}

TEST_CASE(
    "asynchronous replies: completed later from another thread, or cancelled by a disconnect") {
  ServerThread t(config_for("async"));
  std::mutex mutex;
  std::vector<Reply> parked;
  std::atomic<int> cancel_callbacks{0};
  t.server().add_command("slow", [&](const Request&, Reply reply) {
    reply.on_cancel([&] { ++cancel_callbacks; });
    std::lock_guard lock(mutex);
    parked.push_back(std::move(reply));
  });
  t.server().add_command("drop", [](const Request&, Reply) {});
  t.server().add_command("throw", [](const Request&, Reply) { throw std::runtime_error("boom"); });
  REQUIRE_FALSE(t.start());

  auto take = [&]() -> std::optional<Reply> {
    if (!ds1928::test::wait_until([&] {
          std::lock_guard lock(mutex);
          return !parked.empty();
        }))
      return std::nullopt;
    std::lock_guard lock(mutex);
    Reply r = parked.back();
    parked.pop_back();
    return r;
  };

  // Completed later from another thread; the request behind it waits its turn.
  LineClient c(t.server().path());
  c.send_raw(json{{"cmd", "slow"}, {"id", 1}}.dump() + "\n" +
             json{{"cmd", "drop"}, {"id", 2}}.dump() + "\n");
  auto reply = take();
  REQUIRE(reply);
  std::thread later([r = *reply] {
    r.ok({{"value", 5}});
    r.error("late", "second completion is ignored");
  });
  json r = c.reply();
  later.join();
  CHECK(r["ok"] == true);
  CHECK(r["id"] == 1);
  CHECK(r["value"] == 5);
  // A handler that drops its reply: the client still gets an answer.
  r = c.reply();
  CHECK(error_code_of(r) == "internal");
  CHECK(r["id"] == 2);
  r = c.request({{"cmd", "throw"}});
  CHECK(error_code_of(r) == "internal");
  CHECK_THAT(error_message_of(r), Catch::Contains("boom"));

  // The client leaves while its command is still running.
  auto d = std::make_unique<LineClient>(t.server().path());
  d->send_raw(json{{"cmd", "slow"}}.dump() + "\n");
  reply = take();
  REQUIRE(reply);
  CHECK_FALSE(reply->cancelled());
  d.reset();
  CHECK(ds1928::test::wait_until([&] { return reply->cancelled(); }));
  reply->ok({{"value", 1}});  // harmless
  CHECK(t.wait_clients(1));
  CHECK(ds1928::test::wait_until([&] { return cancel_callbacks != 0; }));
  CHECK(cancel_callbacks == 1);
  CHECK(c.request({{"cmd", "drop"}})["ok"] == false);  // c is unaffected
}

TEST_CASE("the server replaces a stale socket file and refuses a live one") {
  SocketConfig cfg = config_for("stale");
  ServerThread first(cfg);
  add_test_commands(first.server());
  REQUIRE_FALSE(first.start());
  {
    boost::asio::io_context io;
    Server second(io, cfg);
    CHECK(second.start() == std::errc::address_in_use);
  }
  LineClient c(cfg.path);
  CHECK(c.request({{"cmd", "echo"}})["ok"] == true);  // the failed start removed nothing

  // A leftover file of a dead server (bound, never listened on) is replaced.
  boost::asio::io_context io;
  const std::string path = temp_socket_path("leftover");
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  {
    boost::asio::local::stream_protocol::acceptor dead(io);
    dead.open();
    dead.bind(path);
  }
  REQUIRE(std::filesystem::exists(path));
  SocketConfig cfg2 = cfg;
  cfg2.path = path;
  ServerThread t(cfg2);
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient d(path);
  CHECK(d.request({{"cmd", "echo"}})["ok"] == true);
}

TEST_CASE("whatever a handler throws is answered, and the server goes on") {
  ServerThread t(config_for("throw"));
  add_test_commands(t.server());
  t.server().add_command("std",
                         [](const Request&, Reply) { throw std::runtime_error("disk on fire"); });
  t.server().add_command("json", [](const Request& req, Reply reply) {
    reply.ok({{"n", req.body().at("n").get<int>()}});  // type_error on a string, out_of_range
  });
  t.server().add_command("odd", [](const Request&, Reply) { throw 42; });
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());
  const json s = c.request({{"cmd", "std"}, {"id", 1}});
  CHECK(error_code_of(s) == "internal");
  CHECK_THAT(error_message_of(s), Catch::Contains("disk on fire"));
  CHECK(s["id"] == 1);
  const json j = c.request({{"cmd", "json"}, {"n", "seven"}});
  CHECK(error_code_of(j) == "bad_argument");
  CHECK_THAT(error_message_of(j), Catch::Contains("type must be number"));
  CHECK(error_code_of(c.request({{"cmd", "json"}})) == "bad_argument");
  CHECK(error_code_of(c.request({{"cmd", "odd"}})) == "internal");
  CHECK(c.request({{"cmd", "echo"}})["ok"] == true);
}

TEST_CASE("JSON beyond what the parser or the server holds is bad_json, not a crash") {
  SocketConfig cfg = config_for("numbers");
  cfg.max_request_bytes = 1024;
  ServerThread t(cfg);
  add_test_commands(t.server());
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());
  // 400 digits: the parser throws out_of_range (not parse_error) for a number beyond a double.
  c.send_raw("{\"cmd\":\"echo\",\"id\":1" + std::string(400, '0') + "}\n");
  const json big = c.reply();
  CHECK(error_code_of(big) == "bad_json");
  CHECK_THAT(error_message_of(big), Catch::Contains("number overflow"));
  c.send_raw("{\"cmd\":\"echo\",\"id\":" + std::string(65, '[') + std::string(65, ']') + "}\n");
  CHECK_THAT(error_message_of(c.reply()), Catch::Contains("nested deeper than 64"));
  // 64 levels are fine, and echoed.
  json id = json::array();
  for (int i = 1; i < 63; ++i) id = json::array({id});  // 63 levels in the request object
  const json deep = c.request({{"cmd", "echo"}, {"id", id}});
  CHECK(deep["ok"] == true);
  CHECK(deep["id"] == id);
  // Brackets and escaped quotes inside strings do not nest.
  const json text = c.request({{"cmd", "echo"}, {"text", std::string(100, '[') + "\"\\"}});
  CHECK(text["ok"] == true);
}

namespace {
// Bytes the kernel holds for one direction of a Unix stream socket, at most: the sender's
// buffer (the default one, the server does not change it) counted twice for skb overhead.
std::size_t kernel_socket_bytes() {
  std::size_t wmem = 212992;
  if (FILE* f = std::fopen("/proc/sys/net/core/wmem_default", "r")) {
    if (std::fscanf(f, "%zu", &wmem) != 1) wmem = 212992;
    std::fclose(f);
  }
  return 2 * wmem;
}
}  // namespace

TEST_CASE("a client that does not read its replies stops being read, then is closed") {
  SocketConfig cfg = config_for("noread");
  cfg.reply_buffer_bytes = 4096;
  cfg.reply_stall_timeout_ms = 200;
  ServerThread t(cfg);
  std::atomic<int> calls{0};
  constexpr std::size_t kReply = 65536;
  t.server().add_command("big", [&](const Request&, Reply reply) {
    ++calls;
    reply.ok({{"data", std::string(kReply, 'd')}});
  });
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path(), 10000);
  std::string requests;
  for (int i = 0; i < 200; ++i) requests += "{\"cmd\":\"big\"}\n";  // 3 kB: one write
  REQUIRE(c.send_raw(requests));
  // Never read: the server stops handling requests once the kernel's buffer and its own
  // 4 kB are full, and closes the connection after 200 ms of that.
  REQUIRE(t.wait_clients(0, 10000));
  const std::size_t bound = 2 + (kernel_socket_bytes() + cfg.reply_buffer_bytes) / kReply;
  INFO("handled " << calls.load() << " of 200 requests; bound " << bound);
  CHECK(calls.load() <= static_cast<int>(bound));
  CHECK(calls.load() < 200);
}

TEST_CASE("a client that reads slowly gets every reply, in order") {
  SocketConfig cfg = config_for("slowread");
  cfg.reply_buffer_bytes = 4096;
  cfg.reply_stall_timeout_ms = 10000;
  ServerThread t(cfg);
  t.server().add_command("big", [](const Request&, Reply reply) {
    reply.ok({{"data", std::string(65536, 'd')}});
  });
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path(), 10000);
  std::string requests;
  for (int i = 1; i <= 100; ++i) requests += "{\"cmd\":\"big\",\"id\":" + std::to_string(i) + "}\n";
  REQUIRE(c.send_raw(requests));
  for (int i = 1; i <= 100; ++i) {
    const json r = c.reply();
    REQUIRE(r.is_object());
    CHECK(r["id"] == i);
    CHECK(r["data"].get<std::string>().size() == 65536);
  }
  CHECK(t.clients() == 1);
}

TEST_CASE("a streaming command sends progress lines before its reply, never after") {
  ServerThread t(config_for("progress"));
  std::atomic<int> refused_after{-1};
  t.server().add_command("stream", [&](const Request&, Reply reply) {
    for (int i = 0; i < 3; ++i) CHECK(reply.progress({{"part", i}}));
    reply.ok({{"parts", 3}});
    // Completed: nothing more reaches the client.
    refused_after = reply.progress({{"part", 99}}) ? 0 : 1;
  });
  REQUIRE_FALSE(t.start());
  LineClient c(t.server().path());
  REQUIRE(c.send_raw("{\"cmd\":\"stream\",\"id\":5}\n"));
  for (int i = 0; i < 3; ++i) {
    const auto line = c.read_line();
    REQUIRE(line);
    const json j = json::parse(*line);
    CHECK(j["part"] == i);
    CHECK(j["id"] == 5);
    CHECK_FALSE(j.contains("ok"));
  }
  const auto last = c.read_line();
  REQUIRE(last);
  CHECK(json::parse(*last)["parts"] == 3);
  CHECK(refused_after == 1);
  // The connection goes on with ordinary requests.
  CHECK(c.request({{"cmd", "stream"}})["part"] == 0);
}
