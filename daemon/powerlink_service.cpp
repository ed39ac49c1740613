#include "powerlink_service.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "capture/capturing_link.hpp"
#include "powerlink/interface_check.hpp"
#include "powerlink/module_phase.hpp"
#include "powerlink/raw_link.hpp"
#include "powerlink/rx_wait.hpp"
#include "powerlink_commands.hpp"

namespace ds1928 {
namespace {

// Boot step "configure" of a CN: objects written, the failures of the last run (index/subindex,
// abort code), and an identity mismatch.
nlohmann::json configuration_json(const powerlink::CnStatus& n) {
  nlohmann::json failures = nlohmann::json::array();
  for (std::size_t i = 0; i < n.last_failure_count; ++i)
    failures.push_back(powerlink::describe(n.last_failures[i]));
  return {{"objects_written", n.objects_written},
          {"object_failures", n.object_failures},
          {"configuration_resets", n.configuration_resets},
          {"configuration_not_verified", n.configuration_not_verified},
          {"last_failures", std::move(failures)},
          {"identity_mismatch",
           n.identity_mismatch ? nlohmann::json(powerlink::describe(n.mismatch)) : nullptr}};
}

// Error signalling of a CN: the handshake, EN/EA, the entries fetched (the last ones, described).
nlohmann::json exception_json(const powerlink::CnStatus& n) {
  nlohmann::json entries = nlohmann::json::array();
  for (std::size_t i = 0; i < n.error_entry_count; ++i) {
    const powerlink::ErrorEntry& e = n.error_entries[i];
    entries.push_back({{"type", e.type},
                       {"code", e.code},
                       {"timestamp_s", static_cast<uint32_t>(e.timestamp)},
                       {"timestamp_ns", static_cast<uint32_t>(e.timestamp >> 32)},
                       {"text", powerlink::describe(e)}});
  }
  return {{"signalling", std::string(powerlink::to_string(n.errsig))},
          {"handshakes", n.errsig_handshakes},
          {"handshakes_given_up", n.errsig_gave_up},
          {"new", n.exception_new},
          {"acknowledged", n.exception_acknowledge},
          {"signalled", n.exceptions_signalled},
          {"error_register", static_cast<unsigned>(n.static_error_bits & 0xFF)},
          {"static_error_bits", n.static_error_bits},
          {"entries_total", n.status_error_entries},
          {"entries", std::move(entries)}};
}

// Where the CN's process image comes from and the PDO mapping it was bound from, entry by entry
// (docs/powerlink.md §Process image from the PDO mapping).
// A figure in µs to 0.01 µs (the wire's resolution is 0.08 µs).
double us(double v) {
  return std::round(v * 100.0) / 100.0;
}

nlohmann::json budget_terms_json(const powerlink::CycleBudget& b) {
  return {{"total_us", us(b.total_us())},
          {"soc_us", us(b.soc_us)},
          {"wait_soc_preq_us", us(b.wait_soc_preq_us)},
          {"prc_nodes", b.prc_nodes},
          {"prc_slot_us", us(b.prc_us)},
          {"polled", b.polled_in_worst_cycle},
          {"isochronous_us", us(b.isochronous_us)},
          {"soa_us", us(b.soa_us)},
          {"async_wait_us", us(b.async_wait_us)},
          {"asnd_us", us(b.asnd_us)}};
}

nlohmann::json occupancy_json(const powerlink::OccupancyHistogram& h) {
  const powerlink::OccupancySummary s = h.summary();
  return {{"count", s.count},
          {"p50_us", us(static_cast<double>(s.p50_ns) / 1e3)},
          {"p99_us", us(static_cast<double>(s.p99_ns) / 1e3)},
          {"max_us", us(static_cast<double>(s.max_ns) / 1e3)}};
}

nlohmann::json image_json(const powerlink::PowerlinkBus& bus, uint8_t node) {
  // Large (two mappings of up to 254 entries): on the heap, once per status request.
  auto img = std::make_unique<powerlink::PowerlinkBus::MappedImage>();
  if (!bus.mapped_image(node, *img)) return nullptr;
  auto entries = [](std::span<const powerlink::PdoMapEntry> list) {
    nlohmann::json out = nlohmann::json::array();
    for (const powerlink::PdoMapEntry& e : list)
      out.push_back({{"index", e.index},
                     {"subindex", e.subindex},
                     {"offset", e.offset_bits / 8},
                     {"length", e.length_bits / 8},
                     {"bit_offset", e.offset_bits},
                     {"bit_length", e.length_bits}});
    return out;
  };
  return {{"source", std::string(powerlink::to_string(img->source))},
          {"error", img->error ? img->error.message() : std::string()},
          {"refused", std::string(img->refusal.data())},
          {"tpdo", entries(std::span(img->tpdo.data(), img->tpdo_count))},
          {"rpdo", entries(std::span(img->rpdo.data(), img->rpdo_count))}};
}

// Whether the CN's inputs reach its axes, and why not: its axes are published stale while it is
// not OPERATIONAL, or while its PRes says RD = 0 (data not ready).
std::string inputs_state(const powerlink::CnStatus& n) {
  if (n.image_source == powerlink::ImageSource::kRefused) return "image_refused";
  if (n.boot != powerlink::CnBootState::kOperational) return "node_not_operational";
  if (!n.pres_ready) return "pres_not_ready";
  return "taken";
}

}  // namespace

PowerlinkService::PowerlinkService(std::unique_ptr<powerlink::PowerlinkBus> bus)
    : owned_(std::move(bus)), bus_(*owned_) {}

PowerlinkService::PowerlinkService(powerlink::PowerlinkBus& bus) : bus_(bus) {}

void PowerlinkService::register_commands(control::Server& server, const SocketConfig& socket) {
  register_powerlink_commands(server, bus_, socket.privileged_group);
}

BusService::Reported PowerlinkService::reported_state() const {
  const auto st = bus_.status();
  const BusState s = bus_.state();
  if (s == BusState::Down) return BusService::reported_state();
  if (!st.link_up) {
    const std::string name = interface_.empty() ? std::string("the interface") : interface_;
    return {"waiting_for_link",
            fmt::format("link down on '{}' (no carrier, or the interface is down): connect the "
                        "cable to the POWERLINK segment, or `ip link set {} up`; cycling starts "
                        "when the carrier comes",
                        name, name)};
  }
  if (st.counters.foreign_mn_at_start) {
    const auto& m = st.counters.foreign_mn_mac;
    return {"another_mn",
            fmt::format("another Managing Node is active on '{}' ({} from "
                        "{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x} while listening, MNWaitNotAct): "
                        "ds1928d stays NOT_ACTIVE and sends nothing, one MN per segment (EPSG DS "
                        "301); stop the other MN or give ds1928d a segment of its own, then "
                        "restart it",
                        interface_.empty() ? std::string("the interface") : interface_,
                        powerlink::to_string(st.counters.foreign_mn_frame), m[0], m[1], m[2], m[3],
                        m[4], m[5])};
  }
  if (s != BusState::Booting) return BusService::reported_state();
  std::string waiting;
  for (std::size_t i = 0; i < st.node_count; ++i) {
    const auto& n = st.nodes[i];
    if (n.boot == powerlink::CnBootState::kOperational) continue;
    waiting += fmt::format("{}node {} {}", waiting.empty() ? "" : ", ", n.node,
                           powerlink::to_string(n.boot));
    if (n.last_error) waiting += " (" + n.last_error.message() + ")";
  }
  return {"booting",
          waiting.empty() ? "the CNs are being started" : "not yet operational: " + waiting};
}

NodePhase PowerlinkService::node_phase(std::size_t axis) const {
  const auto& axes = bus_.config().axes;
  if (axis >= axes.size()) return NodePhase::Unknown;
  const auto st = bus_.status();
  for (std::size_t i = 0; i < st.node_count; ++i) {
    const powerlink::CnStatus& n = st.nodes[i];
    if (n.node != axes[axis].node) continue;
    // Refused for its identity, the CN answered all the same.
    const bool heard =
        n.identified || n.last_error == make_error_code(powerlink::MnError::kIdentMismatch);
    return powerlink::node_phase(n.boot, n.nmt, heard);
  }
  return NodePhase::Unknown;
}

void PowerlinkService::status_extra(nlohmann::json& j) const {
  const auto st = bus_.status();
  j["mn_state"] = std::string(powerlink::to_string(st.mn_state));
  j["link_up"] = st.link_up;
  j["counters"] = {{"cycles", st.counters.cycles},
                   {"cycle_time_exceeded", st.counters.cycle_time_exceeded.events},
                   {"cycle_time_exceeded_fired", st.counters.cycle_time_exceeded.fired},
                   {"unexpected_frames", st.counters.unexpected_frames},
                   {"invalid_frames", st.counters.invalid_frames},
                   {"short_frames", st.counters.short_frames},
                   {"async_timeouts", st.counters.async_timeouts},
                   {"async_invites_unused", st.counters.async_invites_unused},
                   {"foreign_mn_frames", st.counters.foreign_mn_frames}};
  if (st.counters.foreign_mn_frames > 0) {
    const auto& m = st.counters.foreign_mn_mac;
    j["foreign_mn"] = {
        {"at_start", st.counters.foreign_mn_at_start},
        {"last_frame", std::string(powerlink::to_string(st.counters.foreign_mn_frame))},
        {"last_source_mac", fmt::format("{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}", m[0], m[1],
                                        m[2], m[3], m[4], m[5])}};
  }
  if (budget_) {
    const std::string warning = worst_case_warning(*budget_, async_mtu_);
    j["cycle_budget"] = {{"period_us", budget_->period_us},
                         {"async_mtu", async_mtu_},
                         {"nominal", budget_terms_json(budget_->nominal)},
                         {"worst_case", budget_terms_json(budget_->worst)},
                         {"worst_case_fits", budget_->worst_fits()},
                         {"warning", warning.empty() ? nlohmann::json() : nlohmann::json(warning)}};
  }
  // Measured after the SoC: the last PRes (or its timeout), the end of the asynchronous phase.
  j["cycle_occupancy"] = {{"isochronous_end", occupancy_json(bus_.isochronous_end())},
                          {"async_end", occupancy_json(bus_.async_end())}};
  nlohmann::json nodes = nlohmann::json::array();
  for (std::size_t i = 0; i < st.node_count; ++i) {
    const auto& n = st.nodes[i];
    nodes.push_back({{"node", n.node},
                     {"boot", std::string(powerlink::to_string(n.boot))},
                     {"nmt", std::string(powerlink::to_string(n.nmt))},
                     {"in_isochronous", n.in_isochronous},
                     {"vendor_id", n.vendor_id},
                     {"product_code", n.product_code},
                     {"preq_size", n.preq_size},
                     {"pres_size", n.pres_size},
                     {"pres_received", n.pres_received},
                     {"loss_of_pres",
                      {{"events", n.loss_of_pres.events},
                       {"counter", n.loss_of_pres.value},
                       {"fired", n.loss_of_pres.fired},
                       {"threshold", n.loss_of_pres_threshold}}},
                     {"late_pres", {{"events", n.late_pres.events}, {"fired", n.late_pres.fired}}},
                     {"stale_pres_dropped", n.stale_pres_dropped},
                     {"pres_not_ready", n.pres_not_ready},
                     {"pres_ready", n.pres_ready},
                     {"inputs", inputs_state(n)},
                     {"pres_size_mismatches", n.pres_size_mismatches},
                     {"last_pres_size", n.last_pres_size},
                     {"status_error_entries", n.status_error_entries},
                     {"boots", n.boots},
                     {"resets", n.resets},
                     {"sdo_errors", n.sdo_errors},
                     {"multiplex_slot", n.multiplex_slot},
                     {"prc",
                      {{"configured", n.prc_configured},
                       {"active", n.prc},
                       {"fallback", n.prc_fallback},
                       {"pres_time_ns", n.prc_pres_time_ns},
                       {"predecessor", n.prc_predecessor},
                       {"sync_delay_ns", n.prc_sync_delay_ns},
                       {"propagation_ns", n.prc_propagation_ns},
                       {"latency_ns", n.prc_latency_ns},
                       {"outputs_offset", n.prc_outputs_offset},
                       {"outputs_size", n.prc_outputs_size},
                       {"sync_responses", n.sync_responses}}},
                     {"nmt_requests", n.nmt_requests},
                     {"nmt_requests_refused", n.nmt_requests_refused},
                     {"last_error", n.last_error ? n.last_error.message() : std::string()},
                     {"last_reset_reason",
                      n.last_reset_reason ? n.last_reset_reason.message() : std::string()}});
    nodes.back()["image"] = image_json(bus_, n.node);
    nodes.back()["configuration"] = configuration_json(n);
    nodes.back()["exception"] = exception_json(n);
  }
  j["nodes"] = std::move(nodes);
}

void PowerlinkService::watch(std::vector<BusEvent>& events, bool first,
                             std::chrono::steady_clock::time_point now) {
  const auto st = bus_.status();
  uint64_t more = 0;
  const uint32_t ct_fired = st.counters.cycle_time_exceeded.fired;
  if (first) {
    cycle_time_exceeded_.said = ct_fired;
  } else if (cycle_time_exceeded_.due(ct_fired, now, more)) {
    events.push_back(
        {true, fmt::format("powerlink: cycle time exceeded threshold reached {} time(s) (a cycle's "
                           "exchange took longer than the period; {} in total)",
                           more, ct_fired)});
  }
  if (nodes_.size() < st.node_count) nodes_.resize(st.node_count);
  for (std::size_t i = 0; i < st.node_count; ++i) {
    const auto& n = st.nodes[i];
    NodeSeen& seen = nodes_[i];
    if (first) {
      seen.late_pres.said = n.late_pres.fired;
      seen.nmt_refused.said = n.nmt_requests_refused;
      seen.error_entries = n.status_error_entries;
    } else {
      if (n.status_error_entries > seen.error_entries) {
        // The new ones still in the reported window, oldest first.
        const uint32_t fresh = n.status_error_entries - seen.error_entries;
        const std::size_t shown = std::min<std::size_t>(fresh, n.error_entry_count);
        for (std::size_t k = n.error_entry_count - shown; k < n.error_entry_count; ++k)
          events.push_back({true, fmt::format("powerlink node {}: error entry {}", n.node,
                                              powerlink::describe(n.error_entries[k]))});
        if (fresh > shown)
          events.push_back({true, fmt::format("powerlink node {}: {} more error entries", n.node,
                                              fresh - shown)});
      }
      if (n.errsig_gave_up > 0 && !seen.errsig_gave_up_said) {
        seen.errsig_gave_up_said = true;
        events.push_back(
            {true, fmt::format("powerlink node {}: no error signalling handshake (EC did not "
                               "follow ER within {} StatusRequests); the node runs without it, "
                               "EN toggles are still fetched",
                               n.node, powerlink::MnErrorSignalling::kMaxAttempts)});
      }
      if (n.prc_fallback && !seen.prc_fallback_said) {
        seen.prc_fallback_said = true;
        events.push_back({true, fmt::format("powerlink node {}: configured for PollResponse "
                                            "Chaining but its IdentResponse has no PRC feature "
                                            "flag: polled with PReq/PRes instead",
                                            n.node)});
      }
      if (n.resets > seen.resets) {
        std::string reason =
            n.last_reset_reason ? n.last_reset_reason.message() : std::string("unknown reason");
        if (n.identity_mismatch) reason += ": " + powerlink::describe(n.mismatch);
        events.push_back(
            {true,
             fmt::format("powerlink node {}: reset by the MN ({}; resets {}, PRes losses {})",
                         n.node, reason, n.resets, n.loss_of_pres.events),
             control::LogEvent::NodeReset, n.node, -1, reason});
      }
      if (n.object_failures > seen.object_failures) {
        std::string list;
        for (std::size_t k = 0; k < n.last_failure_count; ++k)
          list += (k ? "; " : "") + powerlink::describe(n.last_failures[k]);
        events.push_back({true,
                          fmt::format("powerlink node {}: {} object(s) of its configuration "
                                      "refused ({})",
                                      n.node, n.object_failures - seen.object_failures, list),
                          control::LogEvent::ConfigurationFailed, n.node, -1, list});
      }
      if (n.image_source != seen.image && n.image_source == powerlink::ImageSource::kRefused)
        events.push_back(
            {true, fmt::format("powerlink node {}: process image refused, its axes get no inputs: "
                               "{} ({})",
                               n.node, n.image_refusal.data(), n.image_error.message())});
      else if (n.image_source != seen.image &&
               n.image_source == powerlink::ImageSource::kReadMapping)
        events.push_back(
            n.image_refusal[0] == '\0'
                ? BusEvent{false, fmt::format("powerlink node {}: process image from the node's "
                                              "own PDO mapping (read by SDO)",
                                              n.node)}
                : BusEvent{true,
                           fmt::format("powerlink node {}: process image from the node's own "
                                       "PDO mapping (read by SDO); refused, those axes get no "
                                       "inputs: {}",
                                       n.node, n.image_refusal.data())});
      if (n.boots > seen.boots)
        events.push_back({false,
                          fmt::format("powerlink node {}: operational (boot {})", n.node, n.boots),
                          control::LogEvent::NodeOperational, n.node});
      if (seen.late_pres.due(n.late_pres.fired, now, more))
        events.push_back({true, fmt::format("powerlink node {}: late PRes threshold reached {} "
                                            "time(s) (answers after the PRes timeout; {} in total)",
                                            n.node, more, n.late_pres.fired)});
      if (seen.nmt_refused.due(n.nmt_requests_refused, now, more))
        events.push_back({true, fmt::format("powerlink node {}: {} NMTRequest(s) refused (only a "
                                            "node's own reset is served; {} in total)",
                                            n.node, more, n.nmt_requests_refused)});
    }
    seen.resets = n.resets;
    seen.image = n.image_source;
    seen.boots = n.boots;
    seen.object_failures = n.object_failures;
    seen.error_entries = n.status_error_entries;
  }
}

std::unique_ptr<BusService> make_powerlink_service(const DaemonConfig& config,
                                                   std::string& why_not) {
  const std::string& interface = config.powerlink.interface;
  if (std::string missing = powerlink::interface_missing(interface); !missing.empty()) {
    why_not = "powerlink: " + missing;
    return nullptr;
  }
  if (const std::string shared = powerlink::shared_interface_reason(interface); !shared.empty()) {
    if (!config.powerlink.allow_shared_interface) {
      why_not = fmt::format(
          "powerlink: interface '{}' looks like a port of an IP network, not a POWERLINK segment: "
          "{}. POWERLINK sends SoC and PReq every cycle and needs a port of its own; choose "
          "another interface, or set powerlink.allow_shared_interface: true to use this one",
          interface, shared);
      return nullptr;
    }
    spdlog::warn(
        "powerlink: interface '{}' is shared ({}); used as powerlink."
        "allow_shared_interface says",
        interface, shared);
  }
  auto link = std::make_unique<powerlink::RawLink>();
  powerlink::RawLinkOptions options;
  options.interface = config.powerlink.interface;
  powerlink::apply_rx_wait(config.powerlink.rx_wait, config.powerlink.rx_spin_us, options);
  if (auto ec = link->open(options)) {
    why_not = fmt::format(
        "powerlink: cannot open raw socket on '{}': {}{}", config.powerlink.interface, ec.message(),
        ec == std::errc::operation_not_permitted ? " (needs root or CAP_NET_RAW)" : "");
    return nullptr;
  }
  powerlink::MnConfig mn;
  mn.bus = config.powerlink;
  mn.axes = config.axes;
  mn.cycle_us = config.cycle.period_us;
  mn.mac = link->mac();
  try {
    // Every frame passes the capture point (ds1928ctl capture); it only copies while a capture
    // runs.
    auto tapped = std::make_unique<capture::CapturingLink>(
        std::move(link), config.powerlink.interface, config.capture.ring_frames);
    capture::Tap& tap = tapped->tap();
    tap.set_description("POWERLINK MN raw socket");
    auto service = std::make_unique<PowerlinkService>(
        std::make_unique<powerlink::PowerlinkBus>(mn, std::move(tapped)));
    service->set_interface(interface);
    // The configuration refused a nominal cycle that does not fit; one that fits only while every
    // CN answers in time is said here, in status and in the metrics.
    const PowerlinkCycleBudget budget = powerlink_cycle_budget(config);
    service->set_cycle_budget(budget, config.powerlink.async_mtu);
    spdlog::info("powerlink: cycle budget {:.1f} us nominal, {:.1f} us worst case, of {} us",
                 budget.nominal.total_us(), budget.worst.total_us(), budget.period_us);
    if (const std::string w = worst_case_warning(budget, config.powerlink.async_mtu); !w.empty())
      spdlog::warn("powerlink: {}", w);
    service->add_capture_tap(tap);
    return service;
  } catch (const std::exception& e) {
    why_not = fmt::format("powerlink: {}", e.what());
    return nullptr;
  }
}

}  // namespace ds1928
