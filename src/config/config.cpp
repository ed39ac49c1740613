// YAML → DaemonConfig with complete diagnostics. The document is read into plain structs by a
// small "section" reader that knows which keys it was asked for, so every key left over is an
// unknown key; each value is parsed by hand (not yaml-cpp's as<T>) to get precise messages for
// hex numbers, octal modes, quoted numbers and out-of-range values.
#include <fcntl.h>
#include <unistd.h>
#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "config/config_bus_kinds.hpp"
#include "config/config_canio.hpp"
#include "config/config_info.hpp"
#include "config/config_loader.hpp"
#include "config/config_metrics.hpp"
#include "config/config_powerlink.hpp"
#include "config/config_powerlink_cdc.hpp"
#include "config/config_reader.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {
using namespace config_detail;
namespace {

bool valid_name_char(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
}

// Unix group names as useradd accepts them; empty = leave the group alone.
void group_name(Section& s, std::string_view key, std::string& out) {
  std::string group;
  if (!s.text(key, group, 32)) return;
  const bool ok = group.empty() ||
                  ((std::islower(static_cast<unsigned char>(group[0])) || group[0] == '_') &&
                   std::all_of(group.begin(), group.end(), [](char c) {
                     return std::islower(static_cast<unsigned char>(c)) ||
                            std::isdigit(static_cast<unsigned char>(c)) || c == '_' || c == '-';
                   }));
  if (!ok) {
    s.error(key, "'" + group + "' is not a valid group name (lower-case letters, digits, _ and -)");
    return;
  }
  out = group;
}

// Returns whether the file gives the period (else the MN's concise DCF may).
bool parse_cycle(Section s, CycleConfig& c) {
  const bool period_given = s.has("period_us");
  s.integer("period_us", c.period_us, 100, 100000, "µs");
  s.integer("rt_priority", c.rt_priority, 1, 99, "(SCHED_FIFO)");
  s.integer("cpu", c.cpu, -1, 1023, "(-1 = no affinity)");
  s.integer("spin_us", c.spin_us, 0, 100000, "µs");
  s.boolean("hold_cpu_dma_latency", c.hold_cpu_dma_latency);
  s.boolean("lock_memory", c.lock_memory);
  s.choice("timebase", c.timebase,
           {{"monotonic", TimebaseKind::Monotonic}, {"tai", TimebaseKind::Tai}});
  s.finish();
  return period_given;
}

// axes[].module.<key> accepts what the register behind it accepts under `fm`: the object
// dictionary's range (docs/registers.md), so the configuration and the module never disagree.
template <class T>
bool setting_integer(Section& s, std::string_view key, T& out, const RegisterInfo& reg,
                     FunctionModel fm, std::string_view note = {}) {
  const ValueRange accepted = reg.accepts(fm);
  return s.integer(key, out, accepted.min, accepted.max, note);
}

void parse_module(Section s, ModuleSettings& m, FunctionModel fm) {
  s.boolean("endat_enable", m.endat_enable);
  s.boolean("position_signed", m.position_signed);
  s.boolean("fast_clock_off", m.fast_clock_off);
  s.boolean("sincos_unused", m.sincos_unused);
  setting_integer(s, "prescaler", m.prescaler, setting_register(Setting::Prescaler), fm,
                  "(the EnDat cycle must be at least twice the module cycle)");
  if (setting_integer(s, "slframe_gen_id", m.slframe_gen_id,
                      setting_register(Setting::SlframeGenId), fm) &&
      m.slframe_gen_id != 9 && m.slframe_gen_id != 14) {
    s.error("slframe_gen_id", std::to_string(m.slframe_gen_id) +
                                  " is not allowed; expected 9 (fastest response) or 14 "
                                  "(aligned to the X2X cycle)");
  }
  setting_integer(s, "error_enable", m.error_enable, setting_register(Setting::ErrorEnable), fm);
  const bool have_min =
      setting_integer(s, "vss_min_mv", m.vss_min_mv, setting_register(Setting::VssMin), fm, "mV");
  const bool have_max =
      setting_integer(s, "vss_max_mv", m.vss_max_mv, setting_register(Setting::VssMax), fm, "mV");
  if ((have_min || have_max) && m.vss_min_mv > m.vss_max_mv) {
    s.error(have_min ? "vss_min_mv" : "vss_max_mv", "vss_min_mv (" + std::to_string(m.vss_min_mv) +
                                                        ") must not exceed vss_max_mv (" +
                                                        std::to_string(m.vss_max_mv) + ")");
  }
  setting_integer(s, "quit_time_us", m.quit_time_us, setting_register(Setting::QuitTime), fm, "µs");
  // Function model 0: a control byte and at least one data byte; 254: Tx/RxByte1..5 (datasheet
  // §11.3) and a sequence needs at least 3 bytes (§11.9.4.1.1, "theoretisch: 3 bis 27").
  const bool standard = fm == FunctionModel::Standard;
  const char* note = standard ? "for function model 0"
                              : "for function model 254 (datasheet §11.3: Tx/RxByte1..5; "
                                "§11.9.4.1.1: an MTU holds at least 3 bytes)";
  const RegisterInfo& output_mtu = setting_register(Setting::OutputMtu);
  const RegisterInfo& input_mtu = setting_register(Setting::InputMtu);
  setting_integer(s, "output_mtu", m.output_mtu, output_mtu, fm, note);
  setting_integer(s, "input_mtu", m.input_mtu, input_mtu, fm, note);
  // The struct defaults fit function model 0; under 254 only 5 Tx/Rx bytes exist.
  if (!s.has("output_mtu"))
    m.output_mtu =
        static_cast<uint8_t>(std::min<uint32_t>(m.output_mtu, output_mtu.accepts(fm).max));
  if (!s.has("input_mtu"))
    m.input_mtu = static_cast<uint8_t>(std::min<uint32_t>(m.input_mtu, input_mtu.accepts(fm).max));
  setting_integer(s, "flatstream_mode", m.flatstream_mode,
                  setting_register(Setting::FlatstreamMode), fm,
                  "(bit 0 multi-segment MTU, bit 1 large segments)");
  setting_integer(s, "forward", m.forward, setting_register(Setting::Forward), fm);
  setting_integer(s, "forward_delay_us", m.forward_delay_us,
                  setting_register(Setting::ForwardDelay), fm, "µs");
  s.finish();
}

// Buses whose modules may be placed in the process image by offset ("powerlink").
std::string offset_buses() {
  std::string out;
  for (const BusKindRules& k : bus_kinds())
    if (k.module_offsets) out += (out.empty() ? "" : " or ") + std::string(k.name);
  return out;
}

void parse_axis(Section s, AxisConfig& a, const BusKindRules& bus, size_t index) {
  a.name = "axis" + std::to_string(index);
  a.slot = static_cast<uint8_t>(std::min<size_t>(index + 1, 253));
  a.function_model = bus.function_model.value_or(FunctionModel::Standard);
  if (s.text("name", a.name, 31)) {
    if (a.name.empty() || !std::all_of(a.name.begin(), a.name.end(), valid_name_char)) {
      s.error("name", "'" + a.name +
                          "' is not a valid axis name: 1..31 characters of letters, digits, _ - .");
    }
  }
  s.integer("node", a.node, 1, bus.max_node);
  s.integer("slot", a.slot, 1, 253);
  int64_t fm = 0;
  if (s.integer("function_model", fm, 0, kU8)) {
    if (fm != 0 && fm != 254) {
      s.error(
          "function_model",
          std::to_string(fm) + " is not allowed; expected 0 (standard) or 254 (bus controller)");
    } else if (bus.function_model && fm != static_cast<int64_t>(*bus.function_model)) {
      s.error("function_model", std::to_string(fm) + " is not allowed on bus " +
                                    std::string(bus.name) + "; modules behind a " +
                                    std::string(bus.controller) +
                                    " bus controller run function model " +
                                    std::to_string(static_cast<int>(*bus.function_model)));
    } else {
      a.function_model = static_cast<FunctionModel>(fm);
    }
  }
  parse_module(s.section("module"), a.module, a.function_model);
  s.integer("command_timeout_ms", a.command_timeout_ms, 1, 600000, "ms");
  s.integer("flatstream_timeout_cycles", a.flatstream_timeout_cycles, 1, 1000000);
  for (auto [key, field] :
       {std::pair{"pres_offset", &a.pres_offset}, std::pair{"preq_offset", &a.preq_offset}}) {
    if (!bus.module_offsets && s.has(key)) {
      std::optional<uint16_t> ignored;
      s.optional_integer(key, ignored, 0, 1489);
      s.error(key, "is only meaningful on bus " + offset_buses() + " (the bus here is " +
                       std::string(bus.name) + ")");
      continue;
    }
    s.optional_integer(key, *field, 0, 1489);
  }
  if (s.has("expected_encoder")) {
    Section e = s.section("expected_encoder");
    e.text("id_number", a.expected_encoder.id_number, 32);
    e.text("serial_number", a.expected_encoder.serial_number, 32);
    e.integer("position_bits", a.expected_encoder.position_bits, 1, 64);
    e.finish();
  }
  if (s.has("invalidate_on")) {
    Section v = s.section("invalidate_on");
    for (const ErrorBit& b : error_bits()) {
      bool on = false;
      if (!v.boolean(b.name, on)) continue;
      const auto r = static_cast<std::size_t>(b.reg);
      (on ? a.invalidate_on : a.flag_only_on)[r] |= static_cast<uint16_t>(1u << b.bit);
    }
    v.finish();
  }
  parse_info(s, "info", a);
  s.finish();
}

void parse_sim_axis(Section s, SimAxisConfig& a, const std::filesystem::path& base_dir) {
  s.choice("profile", a.profile,
           {{"constant_velocity", MotionProfile::ConstantVelocity},
            {"sine", MotionProfile::Sine},
            {"stop", MotionProfile::Stop}});
  s.real("velocity_periods_per_s", a.velocity_periods_per_s, -1e9, 1e9);
  s.real("amplitude_periods", a.amplitude_periods, 0, 1e12);
  s.real("frequency_hz", a.frequency_hz, 0, 1000);
  s.integer("module_cycle_us", a.module_cycle_us, 100, 100000, "µs");
  if (s.text("encoder_file", a.encoder_file) && !a.encoder_file.empty()) {
    std::filesystem::path p(a.encoder_file);
    if (p.is_relative()) p = base_dir / p;
    if (const std::string why = unusable_file(p); !why.empty()) {
      s.error("encoder_file", why);
    } else {
      a.encoder_file = p.lexically_normal().string();
    }
  }
  s.integer("inject_error_info", a.inject_error_info, 0, kU8);
  s.integer("endat_error", a.endat_error, 0, 0x7F);
  s.integer("endat_warning", a.endat_warning, 0, 0x1F);
  s.integer("vss_mv", a.vss_mv, 0, 3000, "mV");
  s.integer("supply_mv", a.supply_mv, 0, 6000, "mV");
  s.integer("faults_after_ms", a.faults_after_ms, 0, 3'600'000, "ms");
  s.finish();
}

void parse_shm(Section s, ShmConfig& c) {
  if (s.text("name", c.name, 255)) {
    const bool ok = c.name.size() >= 2 && c.name[0] == '/' &&
                    c.name.find('/', 1) == std::string::npos && c.name != "/." && c.name != "/..";
    if (!ok) {
      s.error("name", "'" + c.name +
                          "' is not a shared-memory name: '/' followed by 1..254 characters "
                          "without '/'");
    }
  }
  s.mode("mode", c.mode);
  group_name(s, "group", c.group);
  s.finish();
}

void parse_socket(Section s, SocketConfig& c) {
  if (s.text("path", c.path, 107) && (c.path.empty() || c.path[0] != '/' || c.path.back() == '/')) {
    s.error("path", "'" + c.path + "' is not an absolute file path");
  }
  s.mode("mode", c.mode);
  group_name(s, "group", c.group);
  group_name(s, "privileged_group", c.privileged_group);
  s.integer("max_clients", c.max_clients, 1, 1024);
  s.integer("max_request_bytes", c.max_request_bytes, 256, 1048576, "bytes");
  s.integer("idle_timeout_ms", c.idle_timeout_ms, 0, 86400000, "ms (0 = never)");
  s.integer("reply_buffer_bytes", c.reply_buffer_bytes, 4096, 67108864, "bytes");
  s.integer("reply_stall_timeout_ms", c.reply_stall_timeout_ms, 100, 86400000, "ms");
  s.finish();
}

void parse_capture(Section s, CaptureConfig& c) {
  if (s.integer("ring_frames", c.ring_frames, 64, 65536, "frames") &&
      (c.ring_frames & (c.ring_frames - 1)) != 0)
    s.error("ring_frames", std::to_string(c.ring_frames) + " is not a power of two");
  s.integer("max_duration_s", c.max_duration_s, 1, 604800, "s");
  s.integer("max_bytes", c.max_bytes, 65536, int64_t{1} << 40, "bytes");
  s.finish();
}

void parse_flight_recorder(Section s, FlightRecorderConfig& c) {
  s.boolean("enabled", c.enabled);
  s.integer("ring_bytes", c.ring_bytes, 65536, int64_t{256} << 20, "bytes");
  s.integer("before_s", c.before_s, 1, 3600, "s");
  s.integer("after_ms", c.after_ms, 0, 10000, "ms");
  if (s.text("dir", c.dir, 1024) && !c.dir.empty() && c.dir.front() != '/')
    s.error("dir", "'" + c.dir + "' is not an absolute path");
  s.integer("max_files", c.max_files, 1, 100000, "files");
  s.integer("max_total_bytes", c.max_total_bytes, 1048576, int64_t{1} << 40, "bytes");
  s.integer("overrun_burst", c.overrun_burst, 0, 1000000, "overruns per second (0 = never)");
  s.finish();
}

// ---------------------------------------------------------------------------------------------

void check_cross_fields(Diagnostics& diag, const DaemonConfig& c, const std::vector<AxisSite>& axes,
                        Loc spin_at) {
  std::map<std::string, size_t> names;
  std::map<std::pair<uint8_t, uint8_t>, size_t> places;
  for (size_t i = 0; i < axes.size() && i < c.axes.size(); ++i) {
    const AxisConfig& a = c.axes[i];
    const AxisSite& site = axes[i];
    if (const auto [it, fresh] = names.emplace(a.name, i); !fresh) {
      diag.error(site.name_at, site.path + ".name",
                 "axis name '" + a.name + "' is already used by axes[" +
                     std::to_string(it->second) + "] (" + where(axes[it->second].at) + ")");
    }
    if (const auto [it, fresh] = places.emplace(std::pair(a.node, a.slot), i); !fresh) {
      diag.error(site.at, site.path,
                 "node " + std::to_string(a.node) + " slot " + std::to_string(a.slot) +
                     " is already used by axes[" + std::to_string(it->second) + "] (" +
                     where(axes[it->second].at) + ")");
    }
  }
  if (c.cycle.spin_us >= c.cycle.period_us) {
    diag.error(spin_at, "cycle.spin_us",
               "spin_us (" + std::to_string(c.cycle.spin_us) +
                   ") must be less than cycle.period_us (" + std::to_string(c.cycle.period_us) +
                   ")");
  }
}

DaemonConfig parse_document(Diagnostics& diag, const YAML::Node& doc, const std::string& name,
                            const std::filesystem::path& base_dir) {
  DaemonConfig c;
  c.source_file = name;
  Section root(diag, doc, "", Loc{1, 1});

  std::vector<std::pair<std::string_view, BusKind>> bus_words;
  for (const BusKindRules& k : bus_kinds()) bus_words.emplace_back(k.name, k.kind);
  root.choice_of("bus", c.bus, bus_words);
  const BusKindRules& bus = bus_kind_rules(c.bus);
  root.choice("log_level", c.log_level,
              {{"trace", std::string("trace")},
               {"debug", std::string("debug")},
               {"info", std::string("info")},
               {"warn", std::string("warn")},
               {"error", std::string("error")},
               {"critical", std::string("critical")},
               {"off", std::string("off")}});
  c.cycle.period_us = bus.default_period_us;
  const bool period_given = parse_cycle(root.section("cycle"), c.cycle);

  PowerlinkSites pl_sites;
  parse_powerlink(root.section("powerlink"), c.powerlink, pl_sites, base_dir);
  // The MN's concise DCF sets the cycle when the file does not (NMT_CycleLen).
  if (c.bus == BusKind::Powerlink && !pl_sites.mn_cdc.empty()) {
    Section powerlink = root.section("powerlink");
    apply_mn_cdc_cycle(powerlink, period_given, c.cycle.period_us, pl_sites.mn_cdc,
                       c.powerlink.sources);
  }
  parse_canio(root.section("canio"), c.canio);
  const bool have_section = root.has(bus.name);
  if (!bus.needs.empty() && !have_section) {
    root.error("bus", "bus is '" + std::string(bus.name) + "' but the file has no " +
                          std::string(bus.name) + " section (" + std::string(bus.needs) + ")");
  }

  std::vector<AxisSite> axis_sites;
  const auto axis_items = root.list("axes");
  for (size_t i = 0; i < axis_items.size(); ++i) {
    const auto& item = axis_items[i];
    AxisConfig axis;
    parse_axis(Section(diag, item.node, item.path, item.at), axis, bus, i);
    const Loc name_at = item.node.IsMap() ? locate(item.node, {"name"}) : item.at;
    const Loc node_at = item.node.IsMap() ? locate(item.node, {"node"}) : item.at;
    const Loc pres_offset_at = item.node.IsMap() ? locate(item.node, {"pres_offset"}) : item.at;
    const Loc preq_offset_at = item.node.IsMap() ? locate(item.node, {"preq_offset"}) : item.at;
    axis_sites.push_back({item.at, name_at, node_at, item.path, pres_offset_at, preq_offset_at});
    c.axes.push_back(std::move(axis));
  }
  if (c.axes.empty()) {
    if (bus.empty_axes == EmptyAxes::OneDefault) {
      AxisConfig axis;
      axis.name = "axis0";
      c.axes.push_back(axis);
    } else if (bus.empty_axes == EmptyAxes::Refused) {
      root.error("axes", "at least one axis is needed on bus " + std::string(bus.name));
    }
  } else if (c.axes.size() > kMaxAxes) {
    root.error("axes", std::to_string(c.axes.size()) + " axes configured; at most " +
                           std::to_string(kMaxAxes) + " are supported");
  }

  {
    Section sim = root.section("simulated");
    const auto sim_items = sim.list("axes");
    for (const auto& item : sim_items) {
      SimAxisConfig axis;
      parse_sim_axis(Section(diag, item.node, item.path, item.at), axis, base_dir);
      c.simulated.axes.push_back(std::move(axis));
    }
    if (sim_items.size() > c.axes.size()) {
      sim.error("axes", std::to_string(sim_items.size()) + " entries but only " +
                            std::to_string(c.axes.size()) +
                            " axes are configured (simulated.axes[i] describes axes[i])");
    }
    sim.finish();
    // Consumers index simulated.axes by axis: one entry per axis, defaults for the rest.
    c.simulated.axes.resize(std::max(c.axes.size(), c.simulated.axes.size()));
  }

  parse_shm(root.section("shm"), c.shm);
  parse_socket(root.section("socket"), c.socket);
  parse_metrics(root.section("metrics"), c.metrics);
  parse_capture(root.section("capture"), c.capture);
  parse_flight_recorder(root.section("flight_recorder"), c.flight_recorder);
  {
    Section t = root.section("topology");
    t.choice("on_mismatch", c.topology.refuse, {{"refuse", true}, {"warn", false}});
    t.finish();
  }
  root.finish();

  check_cross_fields(diag, c, axis_sites, locate(doc, {"cycle", "spin_us"}));
  // Without its required section (reported above) a bus' checks have nothing to look at.
  if (bus.check && (have_section || bus.needs.empty())) {
    bus.check(
        BusDocument{diag, c, doc, axis_sites, have_section, root.value_at(bus.name), pl_sites});
  }
  return c;
}

// Counts the documents of a YAML stream without building them. yaml-cpp 0.7 never advances past
// a flow indicator (',') at document level and reports empty documents there forever, so
// LoadAll() would exhaust memory; a document that starts where the previous one started is that
// case and is reported as a syntax error instead.
class DocumentCounter final : public YAML::EventHandler {
 public:
  void OnDocumentStart(const YAML::Mark& mark) override { starts.push_back(mark); }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}

  std::vector<YAML::Mark> starts;
};

ConfigResult load_text(std::string_view text, const std::string& name,
                       const std::filesystem::path& base_dir) {
  Diagnostics diag(name);
  YAML::Node doc;
  try {
    std::istringstream stream{std::string(text)};
    YAML::Parser parser(stream);
    DocumentCounter counter;
    while (counter.starts.size() < 2 && parser.HandleNextDocument(counter)) {
    }
    if (counter.starts.size() == 2 && counter.starts[0].pos == counter.starts[1].pos) {
      const auto pos = static_cast<size_t>(std::max(0, counter.starts[0].pos));
      const std::string found = pos < text.size() ? "'" + std::string(1, text[pos]) + "'" : "this";
      diag.error(loc_of(counter.starts[0]), "",
                 "YAML syntax error: unexpected " + found + " (not inside a [list] or {map})");
      return ConfigResult(diag.take());
    }
    if (counter.starts.size() > 1) {
      diag.error(loc_of(counter.starts[1]), "",
                 "the file holds more than one YAML document; one is expected");
      return ConfigResult(diag.take());
    }
    doc = YAML::Load(std::string(text));
  } catch (const YAML::DeepRecursion& e) {
    // yaml-cpp's own guard against stack exhaustion; its message is a bare "bad file".
    diag.error(loc_of(e.mark), "",
               "YAML nested deeper than " + std::to_string(e.depth()) +
                   " lists/maps; a ds1928d configuration nests 4 levels");
    return ConfigResult(diag.take());
  } catch (const YAML::Exception& e) {
    diag.error(loc_of(e.mark), "", "YAML syntax error: " + e.msg);
    return ConfigResult(diag.take());
  }
  DaemonConfig config;
  try {
    config = parse_document(diag, doc, name, base_dir);
  } catch (const std::exception& e) {
    // yaml-cpp may throw on exotic documents (e.g. unusual aliases); never let that escape.
    diag.error({}, "", std::string("cannot interpret the document: ") + e.what());
  }
  if (!diag.empty()) return ConfigResult(diag.take());
  return ConfigResult(std::move(config));
}

// ---------------------------------------------------------------------------------------------
// Dump

std::string octal(uint32_t mode) {
  std::array<char, 16> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), mode, 8);
  std::string digits(buf.data(), ec == std::errc{} ? end : buf.data());
  while (digits.size() < 3) digits.insert(digits.begin(), '0');
  return "\"0" + digits + "\"";
}

}  // namespace

// ---------------------------------------------------------------------------------------------

std::string ConfigError::to_string() const {
  std::string out = file;
  if (line > 0) out += ":" + std::to_string(line) + ":" + std::to_string(column);
  out += ": ";
  if (!key.empty()) out += key + ": ";
  return out + message;
}

const std::vector<ConfigError>& ConfigResult::errors() const noexcept {
  static const std::vector<ConfigError> kNone;
  const auto* e = std::get_if<std::vector<ConfigError>>(&value_);
  return e ? *e : kNone;
}

std::string ConfigResult::error_report() const {
  std::string out;
  for (const auto& e : errors()) out += e.to_string() + "\n";
  return out;
}

ConfigResult load_config(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return ConfigResult(std::vector{ConfigError{path, 0, 0, "", "is a directory, not a file"}});
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return ConfigResult(std::vector{ConfigError{path, 0, 0, "", "cannot open the file"}});
  }
  // Read at most one byte past the cap: the path may be /dev/zero or a pipe that never ends.
  std::string text;
  std::array<char, 65536> chunk;
  while (in.read(chunk.data(), chunk.size()) || in.gcount() > 0) {
    text.append(chunk.data(), static_cast<std::size_t>(in.gcount()));
    if (text.size() > kMaxFileBytes) {
      return ConfigResult(
          std::vector{ConfigError{path, 0, 0, "",
                                  "larger than " + std::to_string(kMaxFileBytes) +
                                      " bytes; a ds1928d configuration is a few kB"}});
    }
  }
  if (in.bad()) {
    return ConfigResult(std::vector{ConfigError{path, 0, 0, "", "cannot read the file"}});
  }
  return load_text(text, path, std::filesystem::path(path).parent_path());
}

ConfigResult load_config_from_string(std::string_view text, const std::string& name) {
  return load_text(text, name, std::filesystem::path(name).parent_path());
}

std::string_view to_string(MotionProfile profile) noexcept {
  switch (profile) {
    case MotionProfile::ConstantVelocity:
      return "constant_velocity";
    case MotionProfile::Sine:
      return "sine";
    case MotionProfile::Stop:
      return "stop";
  }
  return "?";
}

std::string fallback_socket_path(std::string_view configured_path) {
  std::string file(configured_path.substr(configured_path.find_last_of('/') + 1));
  if (file.empty()) file = "control.sock";
  if (const char* xdg = std::getenv("XDG_RUNTIME_DIR"); xdg && *xdg == '/') {
    return std::string(xdg) + "/ds1928d/" + file;
  }
  return "/tmp/ds1928d-" + std::to_string(::getuid()) + "/" + file;
}

std::string dump_config(const DaemonConfig& c) {
  std::ostringstream o;
  o << "# effective configuration";
  if (!c.source_file.empty()) o << " of " << c.source_file;
  o << "\nlog_level: " << c.log_level << "\n";
  o << "cycle:\n"
    << "  period_us: " << c.cycle.period_us << source_comment(c.powerlink, "cycle.period_us")
    << "\n"
    << "  rt_priority: " << c.cycle.rt_priority << "\n"
    << "  cpu: " << c.cycle.cpu << "\n"
    << "  spin_us: " << c.cycle.spin_us << "\n"
    << "  hold_cpu_dma_latency: " << yes(c.cycle.hold_cpu_dma_latency) << "\n"
    << "  lock_memory: " << yes(c.cycle.lock_memory) << "\n"
    << "  timebase: " << (c.cycle.timebase == TimebaseKind::Tai ? "tai" : "monotonic") << "\n";
  o << "bus: " << to_string(c.bus) << "\n";
  o << "simulated:\n  axes:" << (c.simulated.axes.empty() ? " []" : "") << "\n";
  for (const auto& a : c.simulated.axes) {
    o << "    - profile: " << to_string(a.profile) << "\n"
      << "      velocity_periods_per_s: " << real_text(a.velocity_periods_per_s) << "\n"
      << "      amplitude_periods: " << real_text(a.amplitude_periods) << "\n"
      << "      frequency_hz: " << real_text(a.frequency_hz) << "\n"
      << "      module_cycle_us: " << a.module_cycle_us << "\n"
      << "      encoder_file: " << quote(a.encoder_file) << "\n"
      << "      inject_error_info: " << hex(a.inject_error_info) << "\n"
      << "      endat_error: " << hex(a.endat_error) << "\n"
      << "      endat_warning: " << hex(a.endat_warning) << "\n"
      << "      vss_mv: " << a.vss_mv << "\n"
      << "      supply_mv: " << a.supply_mv << "\n"
      << "      faults_after_ms: " << a.faults_after_ms << "\n";
  }
  dump_powerlink(o, c.powerlink);
  dump_canio(o, c.canio);
  o << "axes:\n";
  for (const auto& a : c.axes) {
    const auto& m = a.module;
    o << "  - name: " << quote(a.name) << "\n"
      << "    node: " << +a.node << "\n"
      << "    slot: " << +a.slot << "\n"
      << "    function_model: " << +static_cast<uint8_t>(a.function_model) << "\n"
      << "    command_timeout_ms: " << a.command_timeout_ms << "\n"
      << "    flatstream_timeout_cycles: " << a.flatstream_timeout_cycles << "\n";
    if (a.pres_offset) o << "    pres_offset: " << *a.pres_offset << "\n";
    if (a.preq_offset) o << "    preq_offset: " << *a.preq_offset << "\n";
    if (a.expected_encoder.any())
      o << "    expected_encoder:\n"
        << "      id_number: " << quote(a.expected_encoder.id_number) << "\n"
        << "      serial_number: " << quote(a.expected_encoder.serial_number) << "\n";
    if (a.expected_encoder.position_bits != 0)
      o << "      position_bits: " << a.expected_encoder.position_bits << "\n";
    if (a.invalidate_on != ErrorMasks{} || a.flag_only_on != ErrorMasks{}) {
      o << "    invalidate_on:\n";
      for (const ErrorBit& b : error_bits()) {
        const auto r = static_cast<std::size_t>(b.reg);
        const auto m = static_cast<uint16_t>(1u << b.bit);
        if ((a.invalidate_on[r] & m) != 0) o << "      " << b.name << ": true\n";
        if ((a.flag_only_on[r] & m) != 0) o << "      " << b.name << ": false\n";
      }
    }
    if (!a.info.empty()) o << "    info:\n";
    for (const InfoChannelConfig& ch : a.info) {
      o << "      - {name: " << ch.name << ", command: " << hex(ch.request.command)
        << ", mrs: " << hex(ch.request.mrs) << ", parameter: " << +ch.request.parameter;
      if (ch.request.block) o << ", block: " << +*ch.request.block;
      o << ", signed: " << yes(ch.is_signed) << "}\n";
    }
    o << "    module:\n"
      << "      endat_enable: " << yes(m.endat_enable) << "\n"
      << "      position_signed: " << yes(m.position_signed) << "\n"
      << "      fast_clock_off: " << yes(m.fast_clock_off) << "\n"
      << "      sincos_unused: " << yes(m.sincos_unused) << "\n"
      << "      prescaler: " << m.prescaler << "\n"
      << "      slframe_gen_id: " << +m.slframe_gen_id << "\n"
      << "      error_enable: " << hex(m.error_enable) << "\n"
      << "      vss_min_mv: " << m.vss_min_mv << "\n"
      << "      vss_max_mv: " << m.vss_max_mv << "\n"
      << "      quit_time_us: " << m.quit_time_us << "\n"
      << "      output_mtu: " << +m.output_mtu << "\n"
      << "      input_mtu: " << +m.input_mtu << "\n"
      << "      flatstream_mode: " << +m.flatstream_mode << "\n"
      << "      forward: " << +m.forward << "\n"
      << "      forward_delay_us: " << m.forward_delay_us << "\n";
  }
  const auto& s = c.shm;
  o << "shm:\n"
    << "  name: " << quote(s.name) << "\n"
    << "  mode: " << octal(s.mode) << "\n"
    << "  group: " << quote(s.group) << "\n";
  const auto& k = c.socket;
  o << "socket:\n"
    << "  path: " << quote(k.path) << "\n"
    << "  mode: " << octal(k.mode) << "\n"
    << "  group: " << quote(k.group) << "\n"
    << "  privileged_group: " << quote(k.privileged_group) << "\n"
    << "  max_clients: " << k.max_clients << "\n"
    << "  max_request_bytes: " << k.max_request_bytes << "\n"
    << "  idle_timeout_ms: " << k.idle_timeout_ms << "\n"
    << "  reply_buffer_bytes: " << k.reply_buffer_bytes << "\n"
    << "  reply_stall_timeout_ms: " << k.reply_stall_timeout_ms << "\n";
  const auto& m = c.metrics;
  o << "metrics:\n"
    << "  listen: "
    << (m.listen ? quote(m.listen->address.find(':') == std::string::npos
                             ? m.listen->address + ":" + std::to_string(m.listen->port)
                             : "[" + m.listen->address + "]:" + std::to_string(m.listen->port))
                 : quote("off"))
    << "\n"
    << "  max_connections: " << m.max_connections << "\n"
    << "  timeout_ms: " << m.timeout_ms << "\n";
  const auto& cap = c.capture;
  o << "capture:\n"
    << "  ring_frames: " << cap.ring_frames << "\n"
    << "  max_duration_s: " << cap.max_duration_s << "\n"
    << "  max_bytes: " << cap.max_bytes << "\n";
  const auto& fr = c.flight_recorder;
  o << "flight_recorder:\n"
    << "  enabled: " << (fr.enabled ? "true" : "false") << "\n"
    << "  ring_bytes: " << fr.ring_bytes << "\n"
    << "  before_s: " << fr.before_s << "\n"
    << "  after_ms: " << fr.after_ms << "\n"
    << "  dir: " << quote(fr.dir) << "\n"
    << "  max_files: " << fr.max_files << "\n"
    << "  max_total_bytes: " << fr.max_total_bytes << "\n"
    << "  overrun_burst: " << fr.overrun_burst << "\n";
  o << "topology:\n"
    << "  on_mismatch: " << (c.topology.refuse ? "refuse" : "warn") << "\n";
  return o.str();
}

}  // namespace ds1928
