// `position`: reads the axis records straight from shared memory; with --follow waits on the
// futex for each (N-th) publication, says so when the daemon stops or restarts and resumes.
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "client.hpp"
#include "commands.hpp"
#include "ds1928/shm.hpp"
#include "error_bits_text.hpp"

namespace ds1928::ctl {
namespace {

using json = nlohmann::json;

struct PositionOptions {
  std::optional<uint32_t> axis;
  bool follow = false;
  uint32_t every = 1;
  uint64_t count = 0;  // with --follow: stop after this many publications (0: never)
  bool check = false;  // exit kNotValid when a printed axis is not valid
};

const char* validity_name(uint8_t v) {
  switch (v) {
    case DS1928_AXIS_VALID:
      return "valid";
    case DS1928_AXIS_STALE:
      return "stale";
    case DS1928_AXIS_BUS_DOWN:
      return "bus_down";
    case DS1928_AXIS_MODULE_ERROR:
      return "module_error";
    default:
      return "unknown";
  }
}
const char* time_source_name(uint8_t v) {
  switch (v) {
    case DS1928_TIME_NETTIME:
      return "nettime";
    case DS1928_TIME_RX_TIMESTAMP:
      return "rx_timestamp";
    default:
      return "none";
  }
}

ErrorWords words_of(const ds1928_axis_data& d) {
  return {d.error_info, static_cast<uint16_t>(d.endat_error),
          static_cast<uint16_t>(d.endat_warning)};
}

// One configured additional-information channel as the record carries it.
struct InfoChannel {
  uint32_t channel = 0;  // 1..4: EnDatInfo0N
  std::string name;
  int32_t value = 0;
  bool valid = false;
  uint32_t age_us = DS1928_INFO_AGE_NEVER;
};

std::vector<InfoChannel> info_channels(const ShmReader& reader, uint32_t axis,
                                       const ds1928_axis_info& info) {
  std::vector<InfoChannel> out;
  for (uint32_t n = 0; n < DS1928_INFO_CHANNELS; ++n) {
    if ((info.configured & (1u << n)) == 0) continue;
    const char* name = reader.info_name(axis, n);
    out.push_back({n + 1, name != nullptr ? name : "info" + std::to_string(n + 1), info.value[n],
                   (info.valid & (1u << n)) != 0, info.age_us[n]});
  }
  return out;
}

json info_json(const std::vector<InfoChannel>& channels) {
  json out = json::array();
  for (const InfoChannel& c : channels)
    out.push_back({{"channel", c.channel},
                   {"name", c.name},
                   {"value", c.value},
                   {"valid", c.valid},
                   {"age_us", c.age_us == DS1928_INFO_AGE_NEVER ? json(nullptr) : json(c.age_us)}});
  return out;
}

json axis_json(uint32_t axis, const ds1928_axis_data& d, const std::vector<InfoChannel>& info) {
  return {{"axis", axis},
          {"cycle", d.cycle},
          {"state", validity_name(d.validity)},
          {"position_raw", d.position_raw},
          {"periods", d.periods},
          {"fraction", d.fraction},
          {"position_sdc", d.position_sdc},
          {"pos_time_ns", d.pos_time_ns},
          {"pos_time_raw", d.pos_time_raw},
          {"time_source", time_source_name(d.time_source)},
          {"pos_cycle", d.pos_cycle},
          {"new_position", (d.flags & DS1928_AXIS_NEW_POSITION) != 0},
          {"fresh", (d.flags & DS1928_AXIS_FRESH) != 0},
          {"error_info", d.error_info},
          {"endat_error", d.endat_error},
          {"endat_warning", d.endat_warning},
          {"fault", (d.flags & DS1928_AXIS_FAULT) != 0},
          {"warning", (d.flags & DS1928_AXIS_WARNING) != 0},
          {"held", (d.flags & DS1928_AXIS_HELD) != 0},
          {"errors", error_bits_json(words_of(d))},
          {"info", info_json(info)},
          {"publish_ns", d.publish_ns}};
}

void print_axis(const Context& ctx, uint32_t axis, const ds1928_axis_data& d,
                const std::vector<InfoChannel>& info) {
  if (ctx.json) {
    std::cout << axis_json(axis, d, info).dump() << "\n";
    return;
  }
  const double position = static_cast<double>(d.periods) + d.fraction / 65536.0;
  std::printf("cycle %-10" PRIu64 " axis %-2u %-12s %18.6f periods  raw 0x%016" PRIx64
              "  sdc %11" PRId32 "  PosCycle %4d%s  ErrorInfo 0x%02x%s\n",
              d.cycle, axis, validity_name(d.validity), position, d.position_raw, d.position_sdc,
              d.pos_cycle, (d.flags & DS1928_AXIS_NEW_POSITION) ? " new" : "    ", d.error_info,
              (d.flags & DS1928_AXIS_HELD) ? "  held" : "");
  // The additional-information channels, one line: value, and its age when not read this cycle.
  if (!info.empty()) {
    std::string line = "        info";
    for (const InfoChannel& c : info) {
      line += " " + c.name + "=";
      if (c.age_us == DS1928_INFO_AGE_NEVER) {
        line += "none";
        continue;
      }
      line += std::to_string(c.value);
      if (!c.valid) line += " (not ok)";
      if (c.age_us >= 1000) line += " (" + std::to_string(c.age_us / 1000) + " ms old)";
    }
    std::printf("%s\n", line.c_str());
  }
  // Every set bit by name and remedy, printed again only when the bits change (--follow).
  static std::vector<std::pair<uint32_t, ErrorWords>> shown;
  const ErrorWords w = words_of(d);
  auto it =
      std::find_if(shown.begin(), shown.end(), [axis](const auto& e) { return e.first == axis; });
  if (it == shown.end()) {
    shown.emplace_back(axis, ErrorWords{});
    it = shown.end() - 1;
    if (w == ErrorWords{}) return;
  } else if (it->second == w) {
    return;
  }
  it->second = w;
  if (w == ErrorWords{}) {
    std::printf("        error bits cleared\n");
    return;
  }
  print_error_bits(error_bits_json(w));
}

// Stdout in --json mode (scripts follow one stream), stderr otherwise.
void event(const Context& ctx, const json& e, const std::string& text) {
  if (ctx.json) {
    std::cout << e.dump() << std::endl;
  } else {
    std::cerr << "ds1928ctl: " << text << std::endl;
  }
}

// Opens the shared memory, riding over the moment the daemon is still creating it.
std::error_code open_reader(ShmReader& reader, const std::string& name) {
  std::error_code ec;
  for (int i = 0; i < 20; ++i) {
    ec = reader.open(name);
    if (ec != std::errc::resource_unavailable_try_again) return ec;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return ec;
}

std::string open_problem(const std::string& name, std::error_code ec) {
  if (ec == std::errc::no_such_file_or_directory)
    return "no shared memory " + name + " (is ds1928d running?)";
  if (ec == std::errc::protocol_error)
    return name + " is not ds1928d shared memory of ABI version " +
           std::to_string(DS1928_SHM_ABI_VERSION);
  return "cannot map " + name + ": " + ec.message();
}

// `not_valid` (when given) counts the printed axes that are not valid.
bool print_selected(const Context& ctx, const ShmReader& reader, const PositionOptions& opt,
                    int* not_valid = nullptr) {
  const uint32_t first = opt.axis.value_or(0);
  const uint32_t last = opt.axis ? *opt.axis + 1 : reader.axis_count();
  for (uint32_t a = first; a < last; ++a) {
    ds1928_axis_data d{};
    ds1928_axis_info info{};
    // A daemon without the channels: the record alone.
    if (auto ec = reader.has_info() ? reader.read(a, d, info) : reader.read(a, d)) {
      std::cerr << "ds1928ctl: axis " << a << ": " << ec.message() << "\n";
      return false;
    }
    print_axis(ctx, a, d, info_channels(reader, a, info));
    if (not_valid != nullptr && d.validity != DS1928_AXIS_VALID) {
      ++*not_valid;
      std::cerr << "ds1928ctl: not valid: axis " << a << ": " << validity_name(d.validity) << "\n";
    }
  }
  std::cout.flush();
  return true;
}

// Without a wait area (no write permission on <name>.wait) a follower polls.
ShmWait next_publication(const ShmReader& reader, uint64_t& seen, uint32_t every,
                         int64_t deadline_ns) {
  if (reader.can_wait()) {
    std::error_code ec;
    const auto r = reader.wait(seen, every, deadline_ns, ec);
    return ec ? ShmWait::Timeout : r;
  }
  const int64_t step =
      std::max<int64_t>(static_cast<int64_t>(reader.header().cycle_period_ns), 100'000);
  for (;;) {
    uint64_t last = 0;
    if (ds1928_shm_due(&reader.header(), seen, every, &last)) {
      seen = last;
      return ShmWait::Published;
    }
    if (reader.daemon_state() == DS1928_DAEMON_STOPPED) return ShmWait::Stopped;
    if (ds1928_shm_now_ns() >= deadline_ns) return ShmWait::Timeout;
    std::this_thread::sleep_for(std::chrono::nanoseconds(step));
  }
}

int follow(const Context& ctx, ShmReader& reader, const PositionOptions& opt) {
  uint64_t seen = reader.wait_start();
  uint64_t printed = 0;
  for (;;) {
    // A dead daemon is noticed within ~10 cycles or 100 ms, whichever is longer.
    const int64_t period = static_cast<int64_t>(reader.header().cycle_period_ns);
    const int64_t timeout = std::max<int64_t>(100'000'000, 10 * period * opt.every);
    const ShmWait r = next_publication(reader, seen, opt.every, ds1928_shm_now_ns() + timeout);
    if (r == ShmWait::Published) {
      if (!print_selected(ctx, reader, opt)) return kUnavailable;
      if (opt.count != 0 && ++printed >= opt.count) return kOk;
      continue;
    }
    if (r == ShmWait::Timeout && reader.daemon_alive()) continue;

    if (r == ShmWait::Stopped)
      event(ctx, {{"event", "stopped"}, {"generation", reader.generation()}},
            "daemon stopped; waiting for it to start again");
    else
      event(ctx, {{"event", "not_publishing"}, {"generation", reader.generation()}},
            "daemon not publishing (dead or hung); waiting for it to start again");
    // The name now belongs to the next daemon: look for a new generation.
    while (!reader.reopen()) std::this_thread::sleep_for(std::chrono::milliseconds(200));
    event(ctx,
          {{"event", "restarted"},
           {"generation", reader.generation()},
           {"axes", reader.axis_count()}},
          "daemon restarted (generation " + std::to_string(reader.generation()) + ", " +
              std::to_string(reader.axis_count()) + " axes)");
    if (opt.axis && *opt.axis >= reader.axis_count()) {
      std::cerr << "ds1928ctl: axis " << *opt.axis << " does not exist any more\n";
      return kUsage;
    }
    seen = reader.wait_start();
  }
}

int run_position(const Context& ctx, const PositionOptions& opt) {
  std::string problem;
  const std::string name = shm_name_for(ctx, problem);
  if (name.empty()) {
    std::cerr << "ds1928ctl: " << problem << "\n";
    return kUnavailable;
  }
  ShmReader reader;
  if (auto ec = open_reader(reader, name)) {
    std::cerr << "ds1928ctl: " << open_problem(name, ec) << "\n";
    return kUnavailable;
  }
  if (opt.axis && *opt.axis >= reader.axis_count()) {
    std::cerr << "ds1928ctl: axis " << *opt.axis << " does not exist (the daemon has "
              << reader.axis_count() << " axes)\n";
    return kUsage;
  }
  if (opt.follow) return follow(ctx, reader, opt);
  int not_valid = 0;
  if (!print_selected(ctx, reader, opt, &not_valid)) return kUnavailable;
  if (!reader.daemon_alive()) {
    std::cerr << "ds1928ctl: daemon "
              << (reader.daemon_state() == DS1928_DAEMON_STOPPED ? "stopped" : "not publishing")
              << ": these are its last values\n";
    return kUnavailable;
  }
  return opt.check && not_valid > 0 ? kNotValid : kOk;
}

}  // namespace

void add_position_command(CLI::App& app, Context& ctx) {
  auto opt = std::make_shared<PositionOptions>();
  auto* cmd = app.add_subcommand("position", "Axis positions, read directly from shared memory");
  cmd->add_option("--axis,-a", opt->axis, "Only this axis (0-based)");
  auto* follow_flag =
      cmd->add_flag("--follow,-f", opt->follow, "Print every new publication until interrupted");
  cmd->add_option("--every,-n", opt->every,
                  "With --follow: only publications whose cycle index is a multiple of N")
      ->check(CLI::Range(1u, 1'000'000u))
      ->needs(follow_flag);
  cmd->add_option("--count,-c", opt->count, "With --follow: stop after N publications")
      ->needs(follow_flag);
  cmd->add_flag("--check", opt->check,
                "Exit 5 when a printed axis is not valid (stale, bus_down, module_error)")
      ->excludes(follow_flag);
  cmd->callback([&ctx, opt] { ctx.action = [&ctx, opt] { return run_position(ctx, *opt); }; });
}

}  // namespace ds1928::ctl
