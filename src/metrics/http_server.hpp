// The metrics endpoint's HTTP server on the daemon's normal thread (Boost.Asio, the daemon's
// io_context): accepts TCP connections, reads one request with the strict parser
// (http_request.hpp), answers it with the text the render callback builds and closes.
//
// Robustness bounds, each tested against abuse (tests/metrics):
// - at most `max_connections` open at once; beyond, a connection is accepted, told 503 in one
//   non-blocking write and closed, so a flood never queues in the backlog nor grows memory;
// - per connection a fixed kMaxRequestBytes read buffer and the response string, nothing else;
// - `read_timeout` from accept to a complete request (a slow sender is cut), `write_timeout`
//   for the response (a client that does not read is cut);
// - one request per connection (Connection: close), no body accepted.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <system_error>

#include "control/asio.hpp"
#include "metrics/exposition.hpp"

namespace ds1928::metrics {

struct HttpServerOptions {
  boost::asio::ip::tcp::endpoint endpoint;
  uint32_t max_connections = 64;
  std::chrono::milliseconds read_timeout{5000};
  std::chrono::milliseconds write_timeout{5000};
};

// What the server saw, for the ds1928_http_* metrics and the tests.
struct HttpServerCounters {
  uint64_t accepted = 0;
  uint64_t peak_open = 0;  // most connections open at once
  uint64_t refused = 0;    // over max_connections: 503 and closed
  uint64_t responses_ok = 0;
  uint64_t responses_error = 0;  // 4xx/5xx answered
  uint64_t read_timeouts = 0;
  uint64_t write_timeouts = 0;
};

class HttpServer {
 public:
  // Builds the body of GET /metrics. Runs on the io_context's thread.
  using Render = std::function<std::string(Format)>;

  HttpServer(boost::asio::io_context& io, HttpServerOptions options, Render render);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Binds and listens; errors name the address.
  [[nodiscard]] std::error_code start();
  // Closes the listener and every connection. Idempotent.
  void stop();

  // The bound address (the real port when the configuration said port 0).
  [[nodiscard]] boost::asio::ip::tcp::endpoint local_endpoint() const;
  [[nodiscard]] std::size_t connections() const noexcept;
  [[nodiscard]] const HttpServerCounters& counters() const noexcept;

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace ds1928::metrics
