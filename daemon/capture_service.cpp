#include "capture_service.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/steady_timer.hpp>
#include <chrono>

#include "capture/base64.hpp"
#include "capture/can_record.hpp"
#include "capture/pcapng.hpp"
#include "core/clock.hpp"
#include "endat_service.hpp"

namespace ds1928 {
namespace {

using json = nlohmann::json;
using capture::Direction;
using capture::Tap;

// How often the rings are drained: a 4096-frame ring holds ~0.8 s of a busy POWERLINK cycle, so
// this leaves a wide margin on a loaded machine.
constexpr auto kDrainPeriod = std::chrono::milliseconds(20);
// Bytes of capture data per line on the socket (before base64).
constexpr std::size_t kChunkBytes = 48 * 1024;

enum class Format { Pcapng, Candump };

const char* link_name(uint16_t link_type) {
  return link_type == capture::kLinkTypeEthernet       ? "ethernet"
         : link_type == capture::kLinkTypeCanSocketCan ? "can-socketcan"
                                                       : "other";
}

}  // namespace

// One running capture.
struct CaptureService::Run : std::enable_shared_from_this<Run> {
  struct Point {
    Tap* tap = nullptr;
    uint64_t start = 0;  // S: frames numbered start+1.. belong to the capture
    uint64_t end = 0;    // E, once known
    bool ended = false;
    uint64_t written = 0, tx = 0, rx = 0;
    uint64_t last_written = 0;  // sequence number of the last frame written
  };
  struct Frame {
    int64_t time_ns;
    std::size_t point;
    uint64_t seq;
    Direction direction;
    std::vector<uint8_t> bytes;
  };

  CaptureService& service;
  control::Reply reply;
  boost::asio::steady_timer timer;
  Format format = Format::Pcapng;
  control::PeerCredentials peer;
  std::vector<Point> points;
  int64_t mono_to_real = 0;  // CLOCK_REALTIME - CLOCK_MONOTONIC at the start
  int64_t start_real = 0;
  std::chrono::steady_clock::time_point started, deadline;
  bool explicit_duration = false;
  uint64_t max_frames = UINT64_MAX;
  uint64_t max_bytes = UINT64_MAX;
  uint64_t frames = 0, bytes = 0;
  std::string reason;            // why it ended ("" while running)
  std::vector<uint8_t> pending;  // written, not yet sent
  bool finished = false;         // the window is closed; `pending` is the rest
  bool gone = false;

  Run(CaptureService& s, control::Reply r, boost::asio::io_context& io)
      : service(s), reply(std::move(r)), timer(io) {}

  void start() {
    const int64_t mono = rt::now_ns();
    start_real = rt::realtime_ns();
    mono_to_real = start_real - mono;
    started = std::chrono::steady_clock::now();
    if (format == Format::Pcapng) {
      capture::append_section_header(pending, "ds1928d " PROJECT_VERSION);
      for (const Point& p : points) {
        capture::InterfaceDescription idb;
        idb.link_type = p.tap->link_type();
        idb.name = p.tap->name();
        idb.description = p.tap->description();
        capture::append_interface_description(pending, idb);
      }
      bytes = pending.size();
    }
    for (Point& p : points) p.start = p.tap->begin();
    arm();
  }

  void arm() {
    timer.expires_after(kDrainPeriod);
    timer.async_wait([self = weak_from_this()](const boost::system::error_code& ec) {
      if (auto s = self.lock(); s && !ec) s->tick();
    });
  }

  // The window of every point ends now (duration, capture-stop, the configured limit).
  void close_window(std::string why) {
    if (!reason.empty()) return;
    reason = std::move(why);
    for (Point& p : points) {
      p.end = p.tap->finish();
      p.ended = true;
    }
  }
  // The window ends at the last frame written (frame or byte limit): later frames are not part
  // of the capture.
  void close_at_last_written(std::string why) {
    if (!reason.empty()) return;
    reason = std::move(why);
    for (Point& p : points) {
      p.tap->deactivate();
      p.end = std::max(p.start, p.last_written);
      p.ended = true;
    }
  }

  // Moves what the rings hold into the output, in time order across the points.
  void collect() {
    std::vector<Frame> batch;
    for (std::size_t i = 0; i < points.size(); ++i) {
      Point& p = points[i];
      // At most one ring's worth per point per tick: a producer faster than this is what the
      // ring's drop count is for.
      for (std::size_t n = 0; n < p.tap->ring_frames(); ++n) {
        if (!p.tap->pop([&](const capture::TapFrame& f) {
              if (f.seq <= p.start || (p.ended && f.seq > p.end)) return;
              batch.push_back({f.time_ns, i, f.seq, f.direction,
                               std::vector<uint8_t>(f.bytes.begin(), f.bytes.end())});
            }))
          break;
      }
    }
    std::stable_sort(batch.begin(), batch.end(),
                     [](const Frame& a, const Frame& b) { return a.time_ns < b.time_ns; });
    for (const Frame& f : batch) {
      Point& p = points[f.point];
      if (p.ended && f.seq > p.end) continue;  // past a limit reached earlier in this batch
      if (frames >= max_frames) {
        close_at_last_written("count");
        continue;
      }
      const std::size_t before = pending.size();
      const int64_t real = f.time_ns + mono_to_real;
      if (format == Format::Pcapng) {
        capture::append_enhanced_packet(pending, static_cast<uint32_t>(f.point),
                                        static_cast<uint64_t>(real), f.bytes, f.direction);
      } else if (f.bytes.size() == capture::kSocketCanFrameSize) {
        const std::string line =
            capture::candump_line(real, p.tap->name(),
                                  std::span<const uint8_t, capture::kSocketCanFrameSize>(
                                      f.bytes.data(), capture::kSocketCanFrameSize));
        pending.insert(pending.end(), line.begin(), line.end());
      }
      const std::size_t added = pending.size() - before;
      if (bytes + added > max_bytes) {
        pending.resize(before);
        close_at_last_written("size");
        continue;
      }
      bytes += added;
      ++frames;
      ++p.written;
      ++(f.direction == Direction::Outbound ? p.tx : p.rx);
      p.last_written = f.seq;
    }
    if (frames >= max_frames) close_at_last_written("count");
  }

  // Sends what is pending, in lines of kChunkBytes; false when the client's buffer is full.
  bool flush() {
    std::size_t sent = 0;
    bool all = true;
    while (sent < pending.size()) {
      const std::size_t n = std::min(kChunkBytes, pending.size() - sent);
      if (!reply.progress({{"capture_data", capture::base64_encode({pending.data() + sent, n})}})) {
        all = false;
        break;
      }
      sent += n;
    }
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(sent));
    return all;
  }

  void tick() {
    if (gone) return;
    if (reply.cancelled()) return cancel();
    // A client that does not keep up: nothing more is drained until it has read what is
    // queued (the rings fill and count their drops).
    if (!pending.empty() && !flush()) return arm();
    if (!finished) {
      if (std::chrono::steady_clock::now() >= deadline)
        close_window(explicit_duration ? "duration" : "max_duration");
      collect();
      if (!reason.empty()) {
        // The window is closed: take the rest, then the statistics.
        collect();
        finish_file();
        finished = true;
      }
    }
    if (!flush()) return arm();
    if (finished) return complete();
    arm();
  }

  void finish_file() {
    if (format != Format::Pcapng) return;
    const auto now_real = static_cast<uint64_t>(rt::realtime_ns());
    for (std::size_t i = 0; i < points.size(); ++i) {
      const Point& p = points[i];
      capture::InterfaceStatistics isb;
      isb.interface_id = static_cast<uint32_t>(i);
      isb.time_ns = now_real;
      isb.start_time_ns = static_cast<uint64_t>(start_real);
      isb.end_time_ns = now_real;
      isb.received = p.end - p.start;
      isb.dropped = p.end - p.start - p.written;
      capture::append_interface_statistics(pending, isb);
    }
    // The statistics are not counted against max_bytes: they always close the file.
  }

  json summary() const {
    json ifs = json::array();
    for (const Point& p : points) {
      ifs.push_back({{"name", p.tap->name()},
                     {"description", p.tap->description()},
                     {"link_type", link_name(p.tap->link_type())},
                     {"counter_start", p.start},
                     {"counter_end", p.end},
                     {"frames", p.end - p.start},
                     {"captured", p.written},
                     {"tx", p.tx},
                     {"rx", p.rx},
                     {"dropped", p.end - p.start - p.written}});
    }
    return {{"format", format == Format::Pcapng ? "pcapng" : "candump"},
            {"reason", reason},
            {"frames", frames},
            {"bytes", bytes},
            {"duration_s",
             std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()},
            {"interfaces", std::move(ifs)}};
  }

  void complete() {
    gone = true;
    timer.cancel();
    spdlog::info("capture for pid {} uid {} ended ({}): {} frames, {} bytes", peer.pid, peer.uid,
                 reason, frames, bytes);
    reply.ok({{"capture", summary()}});
    for (Point& p : points) p.tap->release();
    service.run_.reset();  // may destroy *this: last statement
  }

  // The client went away (or the daemon stops): the taps stop, the rings are emptied.
  void cancel() {
    if (gone) return;
    gone = true;
    timer.cancel();
    for (Point& p : points) p.tap->release();
    spdlog::info("capture for pid {} uid {} ended: client gone ({} frames written)", peer.pid,
                 peer.uid, frames);
    service.run_.reset();
  }
};

CaptureService::CaptureService(boost::asio::io_context& io, const DaemonConfig& config,
                               std::span<capture::Tap* const> taps)
    : io_(io), config_(config), taps_(taps.begin(), taps.end()) {}

CaptureService::~CaptureService() {
  abort();
}

void CaptureService::abort() noexcept {
  if (auto run = run_) {
    run->reply.error("capture_aborted", "the daemon is stopping");
    run->cancel();
  }
}

json CaptureService::status_json() const {
  json points = json::array();
  for (const Tap* t : taps_) {
    const capture::TapCounters c = t->counters();
    points.push_back({{"name", t->name()},
                      {"description", t->description()},
                      {"link_type", link_name(t->link_type())},
                      {"frames", c.frames},
                      {"tx_frames", c.tx_frames},
                      {"rx_frames", c.rx_frames},
                      {"captured", c.captured},
                      {"dropped", c.dropped},
                      {"ring_frames", t->ring_frames()}});
  }
  json j{{"running", run_ != nullptr}, {"interfaces", std::move(points)}};
  if (run_)
    j["current"] = {{"pid", run_->peer.pid},
                    {"uid", run_->peer.uid},
                    {"format", run_->format == Format::Pcapng ? "pcapng" : "candump"},
                    {"frames", run_->frames},
                    {"bytes", run_->bytes}};
  return j;
}

void CaptureService::register_commands(control::Server& server) {
  using control::Reply;
  using control::Request;
  const std::string group = config_.socket.privileged_group;
  auto denied = [group](const Request& req, const Reply& reply) {
    if (control::peer_is_privileged(req.peer(), group)) return false;
    reply.error(
        "permission_denied",
        "'" + req.command() + "' records the bus traffic: needs uid 0 or group '" + group + "'");
    return true;
  };

  server.add_command("capture", [this, denied](const Request& req, Reply reply) {
    if (denied(req, reply)) return;
    const auto& lim = config_.capture;
    const std::string format = req.opt_string("format").value_or("pcapng");
    if (format != "pcapng" && format != "candump")
      throw control::ArgumentError("argument 'format': '" + format +
                                   "' is not a capture format (pcapng, candump)");
    const uint64_t max_ms = uint64_t{lim.max_duration_s} * 1000;
    const auto duration_ms = req.opt_uint("duration_ms");
    if (duration_ms && (*duration_ms == 0 || *duration_ms > max_ms))
      throw control::ArgumentError(
          fmt::format("argument 'duration_ms': {} is outside 1..{} (capture.max_duration_s = {})",
                      *duration_ms, max_ms, lim.max_duration_s));
    const auto count = req.opt_uint("count");
    if (count && *count == 0) throw control::ArgumentError("argument 'count': must be at least 1");
    if (taps_.empty())
      return reply.error(
          "no_capture_point",
          fmt::format("the '{}' bus has no link or port to capture", to_string(config_.bus)));
    if (format == "candump" && std::any_of(taps_.begin(), taps_.end(), [](const Tap* t) {
          return t->link_type() != capture::kLinkTypeCanSocketCan;
        }))
      throw control::ArgumentError("argument 'format': candump records CAN frames; this bus is '" +
                                   std::string(to_string(config_.bus)) + "' (use pcapng)");
    if (run_) {
      const double age =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - run_->started).count();
      return reply.error(
          "capture_running",
          fmt::format("a capture is already running ({} for pid {} uid {}, started {:.1f} s ago, "
                      "{} frames so far); one at a time: stop it with 'ds1928ctl capture-stop' "
                      "or wait for it",
                      run_->format == Format::Pcapng ? "pcapng" : "candump", run_->peer.pid,
                      run_->peer.uid, age, run_->frames));
    }
    auto run = std::make_shared<Run>(*this, reply, io_);
    run->format = format == "pcapng" ? Format::Pcapng : Format::Candump;
    run->peer = req.peer();
    run->max_bytes = lim.max_bytes;
    if (count) run->max_frames = *count;
    run->explicit_duration = duration_ms.has_value();
    for (Tap* t : taps_) run->points.push_back({t});
    const auto now = std::chrono::steady_clock::now();
    run->deadline = now + std::chrono::milliseconds(duration_ms.value_or(max_ms));
    run_ = run;
    spdlog::info("capture ({}) started for pid {} uid {}{}{}", format, run->peer.pid, run->peer.uid,
                 duration_ms ? fmt::format(", {} ms", *duration_ms) : std::string(),
                 count ? fmt::format(", {} frames", *count) : std::string());
    run->start();
    // A client that disconnects ends the capture at once (not at the next drain).
    reply.on_cancel([weak = std::weak_ptr<Run>(run)] {
      if (auto r = weak.lock()) r->cancel();
    });
  });

  server.add_command("capture-stop", [this, denied](const Request& req, Reply reply) {
    if (denied(req, reply)) return;
    if (!run_) return reply.error("no_capture", "no capture is running");
    run_->close_window("stopped");
    const auto& r = *run_;
    reply.ok({{"stopped", {{"pid", r.peer.pid}, {"uid", r.peer.uid}, {"frames", r.frames}}}});
  });
}

}  // namespace ds1928
