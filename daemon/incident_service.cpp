#include "incident_service.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdlib>

#include "capture/pcapng.hpp"
#include "control/peer_privilege.hpp"
#include "core/clock.hpp"
#include "service/journal.hpp"

namespace ds1928 {
namespace {

using json = nlohmann::json;

// Incidents whose tail runs at once; more are counted and dropped (a storm is one file anyway).
constexpr std::size_t kMaxPending = 32;
// The longest text of a manual mark.
constexpr std::size_t kMaxMarkText = 200;

std::string default_text(IncidentKind kind, int node, int axis) {
  std::string t(incident_kind_name(kind));
  if (node >= 0) t += fmt::format(" node {}", node);
  if (axis >= 0) t += fmt::format(" axis {}", axis);
  return t;
}

// The directory of the files: the configured one, else systemd's StateDirectory.
std::string incident_dir(const FlightRecorderConfig& fr) {
  if (!fr.dir.empty()) return fr.dir;
  if (const char* state = std::getenv("STATE_DIRECTORY"); state != nullptr && *state != '\0') {
    std::string first(state);
    first = first.substr(0, first.find(':'));  // several directories: the first
    return first + "/incidents";
  }
  return {};
}

std::string utc_text(int64_t realtime_ns) {
  const time_t secs = static_cast<time_t>(realtime_ns / 1000000000);
  std::tm tm{};
  ::gmtime_r(&secs, &tm);
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:06}Z", tm.tm_year + 1900, tm.tm_mon + 1,
                     tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                     (realtime_ns % 1000000000) / 1000);
}

}  // namespace

IncidentService::IncidentService(const DaemonConfig& config, std::span<capture::Tap* const> taps,
                                 std::string bus_name)
    : config_(config),
      fr_(config.flight_recorder),
      taps_(taps.begin(), taps.end()),
      bus_name_(std::move(bus_name)),
      enabled_(config.flight_recorder.enabled) {
  if (!enabled_ || taps_.empty()) return;
  const std::size_t per_tap = fr_.ring_bytes / taps_.size();
  for (capture::Tap* t : taps_)
    t->attach_flight_ring(std::max<std::size_t>(per_tap, 4 * (t->max_frame() + 32)));
}

void IncidentService::open() {
  if (!enabled_) return;
  const std::string dir = incident_dir(fr_);
  if (dir.empty()) {
    spdlog::info(
        "flight recorder: no incident directory (flight_recorder.dir unset and not started by "
        "systemd with StateDirectory=): incidents are counted and logged, no file is written");
    return;
  }
  auto store = std::make_unique<IncidentStore>(dir, fr_.max_files, fr_.max_total_bytes);
  if (auto ec = store->open()) {
    spdlog::warn("flight recorder: incident directory {}: {}; no incident file will be written",
                 dir, ec.message());
    return;
  }
  store_ = std::move(store);
  std::size_t ring = 0;
  for (const capture::Tap* t : taps_)
    if (t->flight_ring()) ring += t->flight_ring()->capacity_bytes();
  spdlog::info(
      "flight recorder: {} KiB of frames over {} capture point(s), window {} s before + {} ms "
      "after an incident; files in {} (at most {} files, {} MiB; {} there now)",
      ring / 1024, taps_.size(), fr_.before_s, fr_.after_ms, dir, fr_.max_files,
      fr_.max_total_bytes / 1048576, store_->files());
}

void IncidentService::raise(IncidentKind kind, int node, int axis, std::string text,
                            int64_t time_ns) {
  if (!enabled_) return;
  const auto k = static_cast<std::size_t>(kind);
  if (k < raised_.size()) ++raised_[k];
  if (time_ns == 0) time_ns = rt::now_ns();
  for (IncidentRecord& p : pending_) {
    if (p.kind == kind && p.node == node && p.axis == axis) {
      ++p.count;
      ++joined_;
      return;
    }
  }
  if (pending_.size() >= kMaxPending) {
    ++pending_dropped_;
    return;
  }
  IncidentRecord r;
  r.number = next_number_++;
  r.time_ns = time_ns;
  r.realtime_ns = time_ns + (rt::realtime_ns() - rt::now_ns());
  r.kind = kind;
  r.node = node;
  r.axis = axis;
  r.text = text.empty() ? default_text(kind, node, axis) : std::move(text);
  pending_.push_back(std::move(r));
}

void IncidentService::poll(int64_t now_ns, bool flush) {
  while (auto e = sink_.take()) raise(e->kind, e->node, e->axis, {}, e->time_ns);
  if (pending_.empty()) return;
  if (now_ns == 0) now_ns = rt::now_ns();
  const int64_t tail_ns = int64_t{fr_.after_ms} * 1000000;
  for (std::size_t i = 0; i < pending_.size();) {
    if (flush || now_ns - pending_[i].time_ns >= tail_ns) {
      IncidentRecord r = std::move(pending_[i]);
      pending_.erase(pending_.begin() + static_cast<std::ptrdiff_t>(i));
      write(std::move(r));
    } else {
      ++i;
    }
  }
}

std::vector<uint8_t> IncidentService::build_file(const IncidentRecord& r, int64_t mono_to_real,
                                                 uint64_t& frames, int64_t& first_frame_ns) const {
  const int64_t from = r.time_ns - int64_t{fr_.before_s} * 1000000000;
  const int64_t to = r.time_ns + int64_t{fr_.after_ms} * 1000000;
  struct Item {
    int64_t time_ns;
    uint32_t point;
    capture::FlightFrame frame;
  };
  std::vector<Item> items;
  for (std::size_t i = 0; i < taps_.size(); ++i) {
    const capture::FlightRing* ring = taps_[i]->flight_ring();
    if (!ring) continue;
    for (capture::FlightFrame& f : ring->frames_since(from))
      if (f.time_ns <= to) items.push_back({f.time_ns, static_cast<uint32_t>(i), std::move(f)});
  }
  std::stable_sort(items.begin(), items.end(),
                   [](const Item& a, const Item& b) { return a.time_ns < b.time_ns; });
  // The file must fit the directory's bound: the oldest frames go first.
  const uint64_t limit = store_ ? store_->max_total_bytes() : UINT64_MAX;
  std::size_t first = 0;
  std::vector<uint8_t> out;
  for (;;) {
    out.clear();
    capture::append_section_header(out, "ds1928d " PROJECT_VERSION " flight recorder");
    for (const capture::Tap* t : taps_) {
      capture::InterfaceDescription idb;
      idb.link_type = t->link_type();
      idb.name = t->name();
      idb.description = t->description();
      capture::append_interface_description(out, idb);
    }
    for (std::size_t k = first; k < items.size(); ++k) {
      const Item& it = items[k];
      capture::append_enhanced_packet(out, it.point,
                                      static_cast<uint64_t>(it.time_ns + mono_to_real),
                                      it.frame.bytes, it.frame.direction);
    }
    if (out.size() <= limit || first >= items.size()) break;
    first += std::max<std::size_t>(1, (items.size() - first) / 4);
  }
  frames = items.size() - std::min(first, items.size());
  first_frame_ns = frames != 0 ? items[first].time_ns + mono_to_real : 0;
  return out;
}

void IncidentService::write(IncidentRecord r) {
  const int64_t mono_to_real = r.realtime_ns - r.time_ns;
  if (store_) {
    std::vector<uint8_t> bytes = build_file(r, mono_to_real, r.frames, r.first_frame_ns);
    const std::string name =
        incident_file_name(r.realtime_ns, r.number, incident_kind_name(r.kind), r.node, r.axis);
    if (auto ec = store_->write(name, bytes)) {
      r.error = fmt::format("writing {}/{}: {}", store_->dir(), name, ec.message());
      ++write_failures_;
    } else {
      r.file = store_->dir() + "/" + name;
      r.bytes = bytes.size();
      ++written_;
    }
  } else {
    r.error = "no incident directory";
  }
  const std::string joined = r.count > 1 ? fmt::format(" ({} times)", r.count) : std::string();
  const std::string text =
      r.file.empty()
          ? fmt::format("incident {}: {}{}; no file: {}", r.number, r.text, joined, r.error)
          : fmt::format("incident {}: {}{}; {} frames around it in {}", r.number, r.text, joined,
                        r.frames, r.file);
  control::log_event(spdlog::level::warn,
                     control::EventFields(control::LogEvent::Incident, bus_name_, r.node, r.axis,
                                          {}, incident_kind_name(r.kind), r.file),
                     text);
  records_.push_back(std::move(r));
  while (records_.size() > std::max<uint32_t>(fr_.max_files, 1)) records_.pop_front();
}

json IncidentService::list_json() const {
  json list = json::array();
  for (const IncidentRecord& r : records_) {
    list.push_back({{"number", r.number},
                    {"time", utc_text(r.realtime_ns)},
                    {"time_ns", r.realtime_ns},
                    {"kind", incident_kind_name(r.kind)},
                    {"node", r.node >= 0 ? json(r.node) : json(nullptr)},
                    {"axis", r.axis >= 0 ? json(r.axis) : json(nullptr)},
                    {"text", r.text},
                    {"count", r.count},
                    {"file", r.file.empty() ? json(nullptr) : json(r.file)},
                    {"error", r.error.empty() ? json(nullptr) : json(r.error)},
                    {"frames", r.frames},
                    {"bytes", r.bytes},
                    {"first_frame",
                     r.first_frame_ns != 0 ? json(utc_text(r.first_frame_ns)) : json(nullptr)}});
  }
  // Files of earlier runs still in the directory (this run's are in the list above).
  json earlier = json::array();
  if (store_) {
    for (const IncidentStore::File& f : store_->list()) {
      const std::string path = store_->dir() + "/" + f.name;
      if (std::none_of(records_.begin(), records_.end(),
                       [&](const IncidentRecord& r) { return r.file == path; }))
        earlier.push_back({{"file", path}, {"bytes", f.bytes}});
    }
  }
  return {{"incidents", std::move(list)},
          {"earlier_files", std::move(earlier)},
          {"pending", pending_.size()}};
}

json IncidentService::status_json() const {
  json rings = json::array();
  for (const capture::Tap* t : taps_) {
    const capture::FlightRing* ring = t->flight_ring();
    if (!ring) continue;
    const auto c = ring->counters();
    rings.push_back({{"name", t->name()},
                     {"bytes", ring->capacity_bytes()},
                     {"frames", c.frames},
                     {"overwritten", c.overwritten}});
  }
  json raised = json::object();
  for (std::size_t k = 0; k < kIncidentKindCount; ++k)
    raised[std::string(incident_kind_name(static_cast<IncidentKind>(k)))] = raised_[k];
  return {{"enabled", enabled_},
          {"dir", dir()},
          {"before_s", fr_.before_s},
          {"after_ms", fr_.after_ms},
          {"rings", std::move(rings)},
          {"raised", std::move(raised)},
          {"joined", joined_},
          {"written", written_},
          {"write_failures", write_failures_},
          {"dropped", pending_dropped_ + sink_.dropped()},
          {"files", store_ ? store_->files() : 0},
          {"files_bytes", store_ ? store_->total_bytes() : 0},
          {"files_removed", store_ ? store_->removed() : 0}};
}

void IncidentService::append_metrics(metrics::Exposition& out) const {
  using metrics::Type;
  out.family("ds1928_incidents", Type::Counter,
             "Incidents raised, by kind (the flight recorder writes a file per incident).");
  for (std::size_t k = 0; k < kIncidentKindCount; ++k)
    out.sample({{"kind", incident_kind_name(static_cast<IncidentKind>(k))}}, raised_[k]);
  out.family("ds1928_incident_files_written", Type::Counter,
             "Incident files the flight recorder wrote.");
  out.sample(written_);
  out.family("ds1928_incident_write_failures", Type::Counter,
             "Incidents whose file could not be written (see the journal).");
  out.sample(write_failures_);
  out.family("ds1928_incidents_dropped", Type::Counter,
             "Incidents lost because too many were pending or the cycle thread's queue was full.");
  out.sample(pending_dropped_ + sink_.dropped());
  out.family("ds1928_incident_files", Type::Gauge, "Incident files in the incident directory.");
  out.sample(uint64_t{store_ ? store_->files() : 0});
  out.family("ds1928_incident_files_bytes", Type::Gauge,
             "Bytes of the incident files in the incident directory.", "bytes");
  out.sample(uint64_t{store_ ? store_->total_bytes() : 0});
}

void IncidentService::register_commands(control::Server& server) {
  using control::Reply;
  using control::Request;
  server.add_command("incidents", [this](const Request&, Reply reply) { reply.ok(list_json()); });
  const std::string group = config_.socket.privileged_group;
  server.add_command("incident-mark", [this, group](const Request& req, Reply reply) {
    if (!control::peer_is_privileged(req.peer(), group))
      return reply.error(
          "permission_denied",
          "'incident-mark' writes an incident file: needs uid 0 or group '" + group + "'");
    std::string text = req.opt_string("text").value_or("");
    if (text.size() > kMaxMarkText)
      throw control::ArgumentError(
          fmt::format("argument 'text': {} bytes, at most {}", text.size(), kMaxMarkText));
    for (char& c : text)
      if (static_cast<unsigned char>(c) < 0x20) c = ' ';
    if (!enabled_)
      return reply.error("flight_recorder_off",
                         "the flight recorder is off "
                         "(flight_recorder.enabled: false)");
    const uint64_t number = next_number_;
    const bool joins = std::any_of(pending_.begin(), pending_.end(), [](const IncidentRecord& p) {
      return p.kind == IncidentKind::Manual;
    });
    raise(IncidentKind::Manual, -1, -1, text.empty() ? "manual mark" : "manual mark: " + text);
    // Without a directory the incident is kept in the listing only: the reply says so instead of
    // promising a file in "".
    const std::string where = dir();
    json marked{{"number", joins ? json(nullptr) : json(number)},
                {"joined", joins},
                {"file_after_ms", fr_.after_ms},
                {"dir", where.empty() ? json(nullptr) : json(where)},
                {"file_written", !where.empty()}};
    marked["note"] =
        where.empty()
            ? "no incident directory (flight_recorder.dir is empty and the daemon runs without "
              "systemd's StateDirectory): the incident is in `ds1928ctl incidents`, no file is "
              "written"
            : fmt::format("its file follows in {} ms in {}", fr_.after_ms, where);
    reply.ok({{"marked", std::move(marked)}});
  });
}

}  // namespace ds1928
