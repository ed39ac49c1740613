#include "metrics/http_server.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <list>

#include "metrics/http_request.hpp"

namespace ds1928::metrics {

namespace asio = boost::asio;
using tcp = asio::ip::tcp;

namespace {

std::string error_response(int status, std::string_view reason) {
  std::string body = fmt::format("{} {}: {}\n", status, status_text(status), reason);
  return fmt::format(
      "HTTP/1.1 {} {}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: "
      "{}\r\n{}Connection: close\r\n\r\n{}",
      status, status_text(status), body.size(), status == 405 ? "Allow: GET, HEAD\r\n" : "", body);
}

}  // namespace

struct HttpServer::Impl : std::enable_shared_from_this<HttpServer::Impl> {
  struct Connection;
  using Handle = std::list<std::shared_ptr<Connection>>::iterator;

  Impl(asio::io_context& io_, HttpServerOptions options_, Render render_)
      : io(io_),
        options(std::move(options_)),
        render(std::move(render_)),
        acceptor(io_),
        accept_retry(io_) {}

  asio::io_context& io;
  HttpServerOptions options;
  Render render;
  tcp::acceptor acceptor;
  asio::steady_timer accept_retry;
  std::list<std::shared_ptr<Connection>> connections;
  HttpServerCounters counters;
  bool running = false;

  void accept();
  void close(const std::shared_ptr<Connection>& c);
};

struct HttpServer::Impl::Connection : std::enable_shared_from_this<Connection> {
  Connection(std::weak_ptr<Impl> server_, tcp::socket socket_)
      : server(std::move(server_)), socket(std::move(socket_)), timer(socket.get_executor()) {}

  std::weak_ptr<Impl> server;
  tcp::socket socket;
  asio::steady_timer timer;
  std::array<char, kMaxRequestBytes> buffer{};
  std::size_t used = 0;
  std::string response;
  bool writing = false;
  bool draining = false;
  bool closed = false;
  Handle self;

  void start(std::chrono::milliseconds read_timeout) {
    arm(read_timeout);
    read();
  }

  // One deadline for the whole request (not per read): a sender trickling a byte at a time is
  // cut as surely as a silent one.
  void arm(std::chrono::milliseconds timeout) {
    timer.expires_after(timeout);
    timer.async_wait([c = shared_from_this()](const boost::system::error_code& ec) {
      if (ec || c->closed) return;
      if (auto s = c->server.lock()) {
        // Draining: the response is out, the rest of the request is not worth waiting for.
        if (c->writing && !c->draining)
          ++s->counters.write_timeouts;
        else if (!c->writing)
          ++s->counters.read_timeouts;
        s->close(c);
      }
    });
  }

  void read() {
    socket.async_read_some(
        asio::buffer(buffer.data() + used, buffer.size() - used),
        [c = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
          if (c->closed) return;
          auto s = c->server.lock();
          if (!s) return;
          if (ec) {  // the peer went away (or stop())
            s->close(c);
            return;
          }
          c->used += n;
          const ParseResult r = parse_request(std::string_view(c->buffer.data(), c->used));
          switch (r.state) {
            case ParseResult::State::Incomplete:
              c->read();
              return;
            case ParseResult::State::Rejected:
              ++s->counters.responses_error;
              c->respond(error_response(r.status, r.reason), s->options.write_timeout);
              return;
            case ParseResult::State::Complete:
              break;
          }
          std::string body;
          try {
            body = s->render(r.request.format);
          } catch (const std::exception& e) {
            ++s->counters.responses_error;
            c->respond(error_response(500, e.what()), s->options.write_timeout);
            return;
          }
          ++s->counters.responses_ok;
          std::string head = fmt::format(
              "HTTP/1.1 200 OK\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: "
              "no-store\r\nConnection: close\r\n\r\n",
              content_type(r.request.format), body.size());
          if (r.request.method == Method::Get) head += body;
          c->respond(std::move(head), s->options.write_timeout);
        });
  }

  void respond(std::string text, std::chrono::milliseconds write_timeout) {
    response = std::move(text);
    writing = true;
    arm(write_timeout);
    asio::async_write(socket, asio::buffer(response),
                      [c = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                        if (c->closed) return;
                        auto s = c->server.lock();
                        if (!s) return;
                        if (ec) {
                          s->close(c);
                          return;
                        }
                        // Half-close, then read what the client still sends until it closes:
                        // closing with unread bytes would reset the connection and could destroy
                        // the response before the client read it (a refused oversized request).
                        boost::system::error_code ignored;
                        c->socket.shutdown(tcp::socket::shutdown_send, ignored);
                        c->draining = true;
                        c->arm(s->options.read_timeout);
                        c->drain();
                      });
  }

  // Reads and discards into the fixed buffer until end of stream, error or the timer.
  void drain() {
    socket.async_read_some(
        asio::buffer(buffer),
        [c = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
          if (c->closed) return;
          if (!ec) return c->drain();
          if (auto s = c->server.lock()) s->close(c);
        });
  }
};

void HttpServer::Impl::close(const std::shared_ptr<Connection>& c) {
  if (c->closed) return;
  c->closed = true;
  boost::system::error_code ignored;
  c->timer.cancel();
  c->socket.close(ignored);
  connections.erase(c->self);
}

void HttpServer::Impl::accept() {
  acceptor.async_accept(
      [self = shared_from_this()](const boost::system::error_code& ec, tcp::socket socket) {
        if (!self->running) return;
        if (ec) {
          // Out of descriptors or memory: wait a little instead of spinning on the error.
          if (ec == asio::error::operation_aborted) return;
          self->accept_retry.expires_after(std::chrono::milliseconds(100));
          self->accept_retry.async_wait([self](const boost::system::error_code& e) {
            if (!e && self->running) self->accept();
          });
          return;
        }
        ++self->counters.accepted;
        if (self->connections.size() >= self->options.max_connections) {
          // Told in one non-blocking write that fits any socket buffer, then closed: nothing of it
          // stays behind.
          ++self->counters.refused;
          static const std::string busy =
              error_response(503, "too many connections to the metrics endpoint");
          boost::system::error_code ignored;
          socket.non_blocking(true, ignored);
          (void)socket.write_some(asio::buffer(busy), ignored);
          // What the client sent already is read (once, without waiting): closing with unread
          // bytes would reset the connection and could destroy the 503 before it is read.
          std::array<char, 1024> sink;
          (void)socket.read_some(asio::buffer(sink), ignored);
          socket.shutdown(tcp::socket::shutdown_send, ignored);
          socket.close(ignored);
        } else {
          auto c = std::make_shared<Connection>(self, std::move(socket));
          self->connections.push_front(c);
          c->self = self->connections.begin();
          self->counters.peak_open =
              std::max<uint64_t>(self->counters.peak_open, self->connections.size());
          c->start(self->options.read_timeout);
        }
        self->accept();
      });
}

HttpServer::HttpServer(asio::io_context& io, HttpServerOptions options, Render render)
    : impl_(std::make_shared<Impl>(io, std::move(options), std::move(render))) {}

HttpServer::~HttpServer() {
  stop();
}

std::error_code HttpServer::start() {
  Impl& i = *impl_;
  boost::system::error_code ec;
  i.acceptor.open(i.options.endpoint.protocol(), ec);
  if (!ec) i.acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) i.acceptor.bind(i.options.endpoint, ec);
  if (!ec) i.acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    boost::system::error_code ignored;
    i.acceptor.close(ignored);
    return ec;
  }
  i.running = true;
  i.accept();
  return {};
}

void HttpServer::stop() {
  Impl& i = *impl_;
  i.running = false;
  boost::system::error_code ignored;
  i.acceptor.close(ignored);
  i.accept_retry.cancel();
  while (!i.connections.empty()) {
    const auto c = i.connections.front();
    i.close(c);
  }
}

tcp::endpoint HttpServer::local_endpoint() const {
  boost::system::error_code ec;
  return impl_->acceptor.local_endpoint(ec);
}

std::size_t HttpServer::connections() const noexcept {
  return impl_->connections.size();
}

const HttpServerCounters& HttpServer::counters() const noexcept {
  return impl_->counters;
}

}  // namespace ds1928::metrics
