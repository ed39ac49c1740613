// `capture` / `capture-stop` (docs/socket-protocol.md, docs/operations.md): records what the bus
// driver sends and receives, from the capture Taps the bus kind installed on its links/ports,
// into a pcapng (or candump log) stream sent to the requesting client as it is written. Runs on
// the normal thread (Boost.Asio); the cycle thread only fills the Taps' rings.
#pragma once

#include <boost/asio/io_context.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>

#include "capture/tap.hpp"
#include "config/config.hpp"
#include "control/control_server.hpp"

namespace ds1928 {

class CaptureService {
 public:
  // `taps`: the capture points of the bus (empty: this bus has nothing to capture). They outlive
  // the service.
  CaptureService(boost::asio::io_context& io, const DaemonConfig& config,
                 std::span<capture::Tap* const> taps);
  ~CaptureService();
  CaptureService(const CaptureService&) = delete;
  CaptureService& operator=(const CaptureService&) = delete;

  void register_commands(control::Server& server);
  // The `capture` part of `status`: per capture point the frames seen, captured, dropped; the
  // running capture, if any.
  [[nodiscard]] nlohmann::json status_json() const;
  // Ends a running capture at once (no final data; the client gets an error). Normal thread.
  void abort() noexcept;

  struct Run;

 private:
  boost::asio::io_context& io_;
  const DaemonConfig& config_;
  std::vector<capture::Tap*> taps_;
  std::shared_ptr<Run> run_;  // the running capture, if any
};

}  // namespace ds1928
