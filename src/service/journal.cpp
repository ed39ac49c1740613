#include "service/journal.hpp"

#include <fmt/format.h>
#include <sys/uio.h>
// The records' CODE_FILE/CODE_LINE would name this sink, not the call site: leave them out.
#define SD_JOURNAL_SUPPRESS_LOCATION
#include <systemd/sd-journal.h>

#include <atomic>

namespace ds1928::control {
namespace {

std::atomic<bool> g_structured{false};

struct EventInfo {
  std::string_view name;
  std::string_view id;
};
// Generated once (random 128-bit) and never changed: the journal catalogue keys on them.
constexpr std::array<EventInfo, kLogEventCount> kEvents{{
    {"", ""},
    {"started", "b37d862e8c5e4f418a8a3e23bf094cd6"},
    {"stopping", "0bfff6a4cf344f49ae3ce46b13cbedac"},
    {"start_failed", "ef98043574f545b6a7326f0d7028cd81"},
    {"bus_state", "a4f0030c871f4ed3b13262dbba858d2b"},
    {"node_reset", "1642b70e82c14d7b8287c491010440b9"},
    {"node_operational", "e4ec431b451d4a3bbce962101c20e313"},
    {"bus_off", "04f260348aba4f92849f9c8a2b63bf2c"},
    {"configuration_failed", "68354e098f86424180051be3dd5fc295"},
    {"identification_failed", "83c17cdff8bd4698868c621efd5a4fb6"},
    {"node_silent", "a087dc98f1514459aad81575e8f216ce"},
    {"incident", "bd8f2cbbc56241e084502e014a44e6c9"},
    {"module_error_bits", "ec549993faa44af181fe75161bcdaba9"},
}};

// syslog priorities (sd-journal's PRIORITY field).
int priority(spdlog::level::level_enum l) noexcept {
  switch (l) {
    case spdlog::level::critical:
      return 2;
    case spdlog::level::err:
      return 3;
    case spdlog::level::warn:
      return 4;
    case spdlog::level::info:
      return 6;
    default:
      return 7;
  }
}

// A field value must not contain the framing characters; log text never does, but a reason is
// an error message that could.
void append_clean(std::string& out, std::string_view v) {
  for (char c : v) out += (c == kFieldMark || c == kTextMark || c == '\n') ? ' ' : c;
}

}  // namespace

std::string_view message_id(LogEvent e) noexcept {
  const auto i = static_cast<std::size_t>(e);
  return i < kEvents.size() ? kEvents[i].id : std::string_view();
}

std::string_view event_name(LogEvent e) noexcept {
  const auto i = static_cast<std::size_t>(e);
  return i < kEvents.size() ? kEvents[i].name : std::string_view();
}

void set_structured_logging(bool on) noexcept {
  g_structured.store(on, std::memory_order_relaxed);
}

void log_event(spdlog::level::level_enum level, const EventFields& f, std::string_view text) {
  if (!g_structured.load(std::memory_order_relaxed)) {
    spdlog::log(level, "{}", text);
    return;
  }
  std::string payload;
  payload.reserve(text.size() + 128);
  const auto field = [&](std::string_view name, std::string_view value) {
    payload += kFieldMark;
    payload += name;
    payload += '=';
    append_clean(payload, value);
  };
  if (f.event != LogEvent::None) field("MESSAGE_ID", message_id(f.event));
  if (f.node >= 0) field("DS1928_NODE", std::to_string(f.node));
  if (f.axis >= 0) field("DS1928_AXIS", std::to_string(f.axis));
  if (!f.bus.empty()) field("DS1928_BUS", f.bus);
  if (!f.reason.empty()) field("DS1928_REASON", f.reason);
  if (!f.incident.empty()) field("DS1928_INCIDENT", f.incident);
  if (!f.incident_file.empty()) field("DS1928_INCIDENT_FILE", f.incident_file);
  payload += kTextMark;
  payload += text;
  spdlog::log(level, "{}", payload);
}

SplitRecord split_record(std::string_view payload) noexcept {
  SplitRecord r;
  if (payload.empty() || payload.front() != kFieldMark) {
    r.text = payload;
    return r;
  }
  const auto end = payload.find(kTextMark);
  if (end == std::string_view::npos) {  // not ours after all
    r.text = payload;
    return r;
  }
  std::string_view fields = payload.substr(0, end);
  r.text = payload.substr(end + 1);
  while (!fields.empty() && r.field_count < r.fields.size()) {
    fields.remove_prefix(1);  // kFieldMark
    const auto next = fields.find(kFieldMark);
    r.fields[r.field_count++] = fields.substr(0, next);
    fields = next == std::string_view::npos ? std::string_view() : fields.substr(next);
  }
  return r;
}

void JournalSink::sink_it_(const spdlog::details::log_msg& msg) {
  const std::string_view payload(msg.payload.data(), msg.payload.size());
  const SplitRecord r = split_record(payload);
  const std::string message = fmt::format("MESSAGE={}", r.text);
  const std::string prio = fmt::format("PRIORITY={}", priority(msg.level));
  const std::string ident = "SYSLOG_IDENTIFIER=" + identifier_;
  std::array<iovec, 3 + std::tuple_size_v<decltype(r.fields)>> iov{};
  std::size_t n = 0;
  const auto add = [&](std::string_view s) {
    iov[n].iov_base = const_cast<char*>(s.data());
    iov[n].iov_len = s.size();
    ++n;
  };
  add(message);
  add(prio);
  add(ident);
  for (std::size_t i = 0; i < r.field_count; ++i) add(r.fields[i]);
  // Nothing to do about a journal that refuses a record: the log is where one would say so.
  (void)::sd_journal_sendv(iov.data(), static_cast<int>(n));
}

}  // namespace ds1928::control
