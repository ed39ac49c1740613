#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "client.hpp"
#include "commands.hpp"
#include "endat/number.hpp"
#include "error_bits_text.hpp"

namespace ds1928::ctl {
namespace {

using json = nlohmann::json;

template <class T>
T get(const json& j, const char* key, T fallback) {
  const auto it = j.find(key);
  if (it == j.end() || it->is_null()) return fallback;
  return it->get<T>();
}

std::string hex(uint64_t v, int digits) {
  char buf[24];
  std::snprintf(buf, sizeof(buf), "0x%0*" PRIx64, digits, v);
  return buf;
}

std::string duration_text(double seconds) {
  const auto s = static_cast<uint64_t>(seconds);
  char buf[64];
  if (s >= 86400)
    std::snprintf(buf, sizeof(buf), "%" PRIu64 "d %02" PRIu64 "h %02" PRIu64 "m", s / 86400,
                  s / 3600 % 24, s / 60 % 60);
  else if (s >= 3600)
    std::snprintf(buf, sizeof(buf), "%" PRIu64 "h %02" PRIu64 "m %02" PRIu64 "s", s / 3600,
                  s / 60 % 60, s % 60);
  else
    std::snprintf(buf, sizeof(buf), "%" PRIu64 "m %02" PRIu64 "s", s / 60, s % 60);
  return buf;
}

std::string ns_text(const json& v) {
  if (!v.is_number()) return "-";
  const double ns = v.get<double>();
  char buf[32];
  if (ns >= 1e6)
    std::snprintf(buf, sizeof(buf), "%.2f ms", ns / 1e6);
  else if (ns >= 1e3)
    std::snprintf(buf, sizeof(buf), "%.1f µs", ns / 1e3);
  else
    std::snprintf(buf, sizeof(buf), "%.0f ns", ns);
  return buf;
}

void print_quantiles(const char* label, const json& q) {
  if (!q.is_object()) return;
  std::cout << "  " << label << "p50 " << ns_text(q.value("p50", json())) << ", p99 "
            << ns_text(q.value("p99", json())) << ", p99.9 " << ns_text(q.value("p999", json()))
            << ", max " << ns_text(q.value("max", json())) << "\n";
}

void print_cycle(const json& c) {
  if (!c.is_object()) return;
  std::cout << "  cycle:     " << get<uint64_t>(c, "period_us", 0) << " µs, "
            << get<uint64_t>(c, "count", 0) << " cycles, " << get<uint64_t>(c, "overruns", 0)
            << " overruns, " << get<uint64_t>(c, "skipped", 0) << " skipped\n";
}

void print_axis_line(const json& a) {
  std::printf(
      "    %-3" PRIu64 " %-12s %-13s module %-6s ErrorInfo %s  EnDat error %s  warning %s\n",
      get<uint64_t>(a, "axis", 0), get<std::string>(a, "name", "").c_str(),
      get<std::string>(a, "state", "?").c_str(), get<std::string>(a, "module_state", "?").c_str(),
      hex(get<uint64_t>(a, "error_info", 0), 2).c_str(),
      hex(get<uint64_t>(a, "endat_error", 0), 4).c_str(),
      hex(get<uint64_t>(a, "endat_warning", 0), 4).c_str());
  if (a.contains("identity_reason"))
    std::printf("        encoder %s: %s\n", get<std::string>(a, "identity", "").c_str(),
                get<std::string>(a, "identity_reason", "").c_str());
  // What the module's red e-LED would flash (its ErrorInfo bits by the datasheet's LED table).
  if (const auto e = get<std::string>(a, "module_error_class", "none"); e != "none") {
    const json m = a.value("module", json::object());
    std::printf("        module e-LED %s: %s\n", get<std::string>(m, "e_led", "?").c_str(),
                e.c_str());
  }
  print_error_bits(a.value("errors", json::array()));
}

// The cycle engine's text already says "real-time: ..." or "not real-time: ...": shown after
// the yes/no without saying it twice.
std::string rt_detail(const std::string& text) {
  for (const char* prefix : {"real-time: ", "not real-time: "}) {
    const std::string p(prefix);
    if (text.compare(0, p.size(), p) == 0) return text.substr(p.size());
  }
  return text;
}

void print_powerlink_nodes(const json& b) {
  for (const auto& n : b.value("nodes", json::array())) {
    std::cout << "    node " << get<uint64_t>(n, "node", 0) << ": "
              << get<std::string>(n, "boot", "?") << " (NMT " << get<std::string>(n, "nmt", "?")
              << "), boots " << get<uint64_t>(n, "boots", 0) << ", resets "
              << get<uint64_t>(n, "resets", 0);
    if (const auto why = get<std::string>(n, "last_reset_reason", ""); !why.empty())
      std::cout << " (last: " << why << ")";
    std::cout << ", PRes losses "
              << get<uint64_t>(n.value("loss_of_pres", json::object()), "events", 0) << "\n";
    // Error signalling: the handshake's state and the error entries fetched from the CN.
    const json x = n.value("exception", json::object());
    if (x.contains("signalling")) {
      std::cout << "      error signalling " << get<std::string>(x, "signalling", "?")
                << ", error register " << hex(get<uint64_t>(x, "error_register", 0), 2)
                << ", entries " << get<uint64_t>(x, "entries_total", 0) << "\n";
      for (const auto& e : x.value("entries", json::array()))
        std::cout << "        " << get<std::string>(e, "text", "?") << "\n";
    }
  }
}

// CAN-I/O: the controller, then each CANopen node (NMT state, heartbeat) with its axes'
// sampling (samples, missing, late frames) and their last error. "nodes" holds one entry per
// axis, "canopen_nodes" one per node.
void print_canio_nodes(const json& b) {
  if (b.contains("interface")) {
    std::cout << "    interface " << get<std::string>(b, "interface", "?") << " ("
              << get<std::string>(b, "transport", "?") << "), "
              << get<std::string>(b, "can_state", "?") << ", " << get<uint64_t>(b, "bitrate", 0)
              << " bit/s\n";
  }
  const json axes = b.value("nodes", json::array());
  auto print_axes_of = [&](uint64_t node) {
    for (const auto& a : axes) {
      if (get<uint64_t>(a, "node", 0) != node) continue;
      std::cout << "      axis " << get<uint64_t>(a, "axis", 0) << ": "
                << get<std::string>(a, "state", "?");
      if (const auto why = get<std::string>(a, "reason", ""); !why.empty())
        std::cout << " (" << why << ")";
      std::cout << ", samples " << get<uint64_t>(a, "samples", 0) << ", missing "
                << get<uint64_t>(a, "missing", 0) << ", late " << get<uint64_t>(a, "late_frames", 0)
                << "\n";
      if (const auto last = get<std::string>(a, "last_error", ""); !last.empty())
        std::cout << "        last error: " << last << "\n";
    }
  };
  std::vector<uint64_t> shown;
  for (const auto& n : b.value("canopen_nodes", json::array())) {
    const uint64_t node = get<uint64_t>(n, "node", 0);
    shown.push_back(node);
    std::cout << "    node " << node << ": NMT " << get<std::string>(n, "nmt_state", "?");
    if (get<bool>(n, "heartbeat_watched", false))
      std::cout << ", heartbeats " << get<uint64_t>(n, "heartbeats", 0) << " ("
                << get<uint64_t>(n, "heartbeat_misses", 0) << " missed)";
    else
      std::cout << ", heartbeat not watched";
    std::cout << ", boot-ups " << get<uint64_t>(n, "boot_ups", 0) << ", EMCY "
              << get<uint64_t>(n, "emcys", 0) << "\n";
    print_axes_of(node);
  }
  // Axes of a node the daemon has no CANopen entry for (none today): still shown.
  for (const auto& a : axes) {
    const uint64_t node = get<uint64_t>(a, "node", 0);
    if (std::find(shown.begin(), shown.end(), node) != shown.end()) continue;
    shown.push_back(node);
    std::cout << "    node " << node << ":\n";
    print_axes_of(node);
  }
}

// POWERLINK: the configuration's cycle budget and the measured occupancy after the SoC.
void print_powerlink_budget(const json& b) {
  if (b.contains("cycle_budget")) {
    const json c = b["cycle_budget"];
    std::printf("    cycle budget: %.1f us nominal, %.1f us worst case, of %" PRIu64 " us%s\n",
                get<double>(c.value("nominal", json::object()), "total_us", 0.0),
                get<double>(c.value("worst_case", json::object()), "total_us", 0.0),
                get<uint64_t>(c, "period_us", 0),
                get<bool>(c, "worst_case_fits", true)
                    ? ""
                    : " (the worst case does not fit: a CN answering at its PRes timeout "
                      "overruns the cycle)");
  }
  if (b.contains("cycle_occupancy")) {
    const json o = b["cycle_occupancy"];
    for (const auto& [key, label] : {std::pair{"isochronous_end", "isochronous phase ends"},
                                     std::pair{"async_end", "async phase ends"}}) {
      const json h = o.value(key, json::object());
      if (get<uint64_t>(h, "count", 0) == 0) continue;
      std::printf("    %s after the SoC: p50 %.1f us, p99 %.1f us, max %.1f us\n", label,
                  get<double>(h, "p50_us", 0.0), get<double>(h, "p99_us", 0.0),
                  get<double>(h, "max_us", 0.0));
    }
  }
}

void print_status(const json& r) {
  const json d = r.value("daemon", json::object());
  std::cout << "ds1928d " << get<std::string>(d, "version", "?") << " (pid "
            << get<int64_t>(d, "pid", 0) << "), " << get<std::string>(d, "state", "?") << ", up "
            << duration_text(get<double>(d, "uptime_s", 0.0)) << "\n";
  std::cout << "  real-time: " << (get<bool>(d, "realtime", false) ? "yes" : "no");
  if (const auto t = rt_detail(get<std::string>(d, "rt_status", "")); !t.empty())
    std::cout << " (" << t << ")";
  std::cout << "\n";
  const json b = r.value("bus", json::object());
  const std::string kind = get<std::string>(b, "kind", "?");
  std::cout << "  bus:       " << kind << ", " << get<std::string>(b, "state", "?");
  if (b.contains("mn_state")) std::cout << " (MN " << get<std::string>(b, "mn_state", "?") << ")";
  std::cout << "\n";
  if (const auto cause = get<std::string>(b, "cause", ""); !cause.empty())
    std::cout << "    cause: " << cause << "\n";
  print_powerlink_budget(b);
  if (kind == "canio")
    print_canio_nodes(b);
  else
    print_powerlink_nodes(b);
  print_cycle(r.value("cycle", json()));
  const json axes = r.value("axes", json::array());
  std::cout << "  axes:      " << axes.size() << "\n";
  for (const auto& a : axes) print_axis_line(a);
}

// --check: the axes of a status reply that are not valid, as "axis 0 (x): bus_down" lines.
std::vector<std::string> invalid_axes(const json& r) {
  std::vector<std::string> bad;
  for (const auto& a : r.value("axes", json::array())) {
    const std::string state = get<std::string>(a, "state", "?");
    if (state == "valid") continue;
    bad.push_back("axis " + std::to_string(get<uint64_t>(a, "axis", 0)) + " (" +
                  get<std::string>(a, "name", "") + "): " + state);
  }
  return bad;
}

int run_status(const Context& ctx, bool check) {
  const Outcome o = send_request(ctx, {{"cmd", "status"}});
  if (const int rc = print_outcome(ctx, o, print_status); rc != kOk) return rc;
  if (!check) return kOk;
  const auto bad = invalid_axes(o.reply);
  for (const auto& line : bad) std::cerr << "ds1928ctl: not valid: " << line << "\n";
  return bad.empty() ? kOk : kNotValid;
}

void print_axes(const json& r) {
  for (const auto& a : r.value("axes", json::array())) {
    print_axis_line(a);
    const uint64_t raw = get<uint64_t>(a, "position_raw", 0);
    std::printf("        node %" PRIu64 " slot %" PRIu64 ", position %" PRId64 " + %" PRIu64
                "/65536 periods (raw %s), PosCycle %" PRId64 "\n",
                get<uint64_t>(a, "node", 0), get<uint64_t>(a, "slot", 0),
                get<int64_t>(a, "periods", 0), get<uint64_t>(a, "fraction", 0),
                hex(raw, 16).c_str(), get<int64_t>(a, "pos_cycle", 0));
  }
}

void print_stats(const json& r) {
  const json c = r.value("cycle", json::object());
  std::cout << "cycle statistics";
  if (r.contains("since_reset_s"))
    std::cout << " (since " << duration_text(get<double>(r, "since_reset_s", 0.0)) << ")";
  std::cout << "\n";
  print_cycle(c);
  print_quantiles("wake-up:   ", c.value("wake_latency_ns", json()));
  print_quantiles("work:      ", c.value("work_ns", json()));
  const json b = r.value("bus", json::object());
  if (!b.empty()) {
    std::cout << "  bus:       " << get<uint64_t>(b, "frames_lost", 0) << " frames lost";
    if (b.contains("state")) std::cout << ", " << get<std::string>(b, "state", "?");
    std::cout << "\n";
  }
}

}  // namespace

void add_basic_commands(CLI::App& app, Context& ctx) {
  auto* status =
      app.add_subcommand("status", "Daemon, real-time, bus, axis states, cycle counters");
  auto check = std::make_shared<bool>(false);
  status->add_flag("--check", *check,
                   "Exit 5 when any axis is not valid (stale, bus_down, module_error)");
  status->callback(
      [&ctx, check] { ctx.action = [&ctx, check] { return run_status(ctx, *check); }; });

  app.add_subcommand("axes", "Configuration and last sample of every axis (over the socket)")
      ->callback([&ctx] {
        ctx.action = [&ctx] { return request_and_print(ctx, {{"cmd", "axes"}}, print_axes); };
      });

  app.add_subcommand("stats", "Cycle statistics: wake-up latency, work time, overruns, losses")
      ->callback([&ctx] {
        ctx.action = [&ctx] { return request_and_print(ctx, {{"cmd", "stats"}}, print_stats); };
      });

  app.add_subcommand("stats-reset", "Reset the cycle statistics")->callback([&ctx] {
    ctx.action = [&ctx] {
      return request_and_print(ctx, {{"cmd", "stats-reset"}},
                               [](const json&) { std::cout << "statistics reset\n"; });
    };
  });

  auto* ack = app.add_subcommand(
      "ack",
      "Acknowledge module errors: write BITS to AckErrorInfo, or --register: EnDatAck bit 0");
  auto axis = std::make_shared<std::string>();
  auto bits = std::make_shared<std::string>();
  auto via_register = std::make_shared<bool>(false);
  ack->add_option("AXIS", *axis, "Axis index (0-based)")->required();
  ack->add_option("BITS", *bits, "ErrorInfo bits to acknowledge, decimal or 0x hex (0..255)");
  ack->add_flag("--register", *via_register,
                "Acknowledge the encoder's EnDatError/EnDatWarning through the module register "
                "EnDatAck bit 0 (and wait until the module did)");
  ack->callback([&ctx, axis, bits, via_register] {
    const auto a = endat::parse_number(*axis, 0, 0xFFFF);
    if (!a) throw CLI::ValidationError("AXIS", "'" + *axis + "': " + a.error().message());
    if (*via_register) {
      if (!bits->empty()) throw CLI::ValidationError("BITS", "not with --register");
      ctx.action = [&ctx, a = *a] {
        return request_and_print(
            ctx, {{"cmd", "endat-ack-register"}, {"axis", a}}, [](const json& r) {
              std::cout << "axis " << get<uint64_t>(r, "axis", 0) << ": EnDatAck acknowledge "
                        << (get<bool>(r, "confirmed", false) ? "done"
                                                             : "written (completion not readable)")
                        << "\n";
            });
      };
      return;
    }
    if (bits->empty()) throw CLI::ValidationError("BITS", "required (or --register)");
    const auto b = endat::parse_u8(*bits);
    if (!b) throw CLI::ValidationError("BITS", "'" + *bits + "': " + b.error().message());
    ctx.action = [&ctx, a = *a, b = *b] {
      return request_and_print(
          ctx, {{"cmd", "ack-errors"}, {"axis", a}, {"bits", b}}, [](const json& r) {
            std::cout << "axis " << get<uint64_t>(r, "axis", 0) << ": acknowledged "
                      << hex(get<uint64_t>(r, "bits", 0), 2) << "\n";
          });
    };
  });
}

}  // namespace ds1928::ctl
