// The daemon's side of a bus: beside the cycle interface (core/bus.hpp BusDriver) every bus kind
// contributes its part of `status`, its own socket commands and the log lines that explain gaps in
// the positions. The daemon creates buses only through make_bus_service() and talks to them only
// through this interface: no code outside a bus kind's own files knows its concrete type.
#pragma once

#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "config/config.hpp"
#include "control/control_server.hpp"
#include "core/bus.hpp"
#include "metrics/exposition.hpp"
#include "service/journal.hpp"
#include "x20ds1928/module_state.hpp"

namespace ds1928::capture {
class Tap;
}

namespace ds1928 {

// One log line about the bus, worded for the journal, with its journal fields (journal.hpp).
struct BusEvent {
  BusEvent() = default;
  BusEvent(bool warning_, std::string text_, control::LogEvent event_ = control::LogEvent::None,
           int node_ = -1, int axis_ = -1, std::string reason_ = {})
      : warning(warning_),
        text(std::move(text_)),
        event(event_),
        node(node_),
        axis(axis_),
        reason(std::move(reason_)) {}

  bool warning = false;
  std::string text;
  control::LogEvent event = control::LogEvent::None;
  int node = -1;       // DS1928_NODE, -1: none
  int axis = -1;       // DS1928_AXIS, -1: none
  std::string reason;  // DS1928_REASON
};

// A counter whose increases are reported, rate-limited: thresholds that only count (cycle time
// exceeded, late PRes, bus errors) are said at most once per kRepeat with how often they fired.
struct SaidCounter {
  static constexpr std::chrono::seconds kRepeat{1};
  uint64_t said = 0;  // value when last reported
  std::chrono::steady_clock::time_point at{};
  // True (and `more` set) when `value` grew and the last report is old enough.
  bool due(uint64_t value, std::chrono::steady_clock::time_point now, uint64_t& more);
};

class BusService {
 public:
  virtual ~BusService() = default;

  [[nodiscard]] virtual BusDriver& driver() noexcept = 0;
  [[nodiscard]] const BusDriver& driver() const noexcept {
    return const_cast<BusService*>(this)->driver();
  }

  // The bus' state as `status` says it, and why when it is not "operational": the driver's
  // state, refined by the kind (CAN-I/O: "degraded" while some nodes answer and others do not,
  // "no_nodes" while none does; POWERLINK: "waiting_for_link"). Normal thread.
  struct Reported {
    std::string state;
    std::string cause;  // empty when operational
  };
  [[nodiscard]] virtual Reported reported_state() const;
  // Why the bus gives an axis no data, in the bus' own words (a node's SDO timeout); empty when
  // the bus knows no reason.
  [[nodiscard]] virtual std::string axis_cause(std::size_t axis) const;
  // What the bus shows of the node that holds the axis' module, for its module state
  // (module_leds.hpp). The default, for a bus without node states (simulated), follows the
  // driver's state.
  [[nodiscard]] virtual NodePhase node_phase(std::size_t axis) const;

  // {"kind", "state", "cause"} plus what the kind adds (status_extra). Normal thread.
  [[nodiscard]] nlohmann::json status_json() const;
  // The bus kind's own socket commands (names listed by bus_commands()).
  virtual void register_commands(control::Server& server, const SocketConfig& socket);
  // Why start() failed, beyond the error code (file:line of an encoder file...); may be empty.
  [[nodiscard]] virtual std::string start_detail() const { return {}; }
  // Kind-specific log lines since the last call. `first`: the baseline look, say nothing.
  virtual void watch(std::vector<BusEvent>& events, bool first,
                     std::chrono::steady_clock::time_point now);
  // The kind's metric families for the OpenMetrics endpoint (daemon_metrics.cpp). Normal thread.
  virtual void append_metrics(metrics::Exposition& out) const;

  // The capture points the bus kind installed on its links/ports (`ds1928ctl capture`); they
  // live as long as the service. Empty: nothing to capture (simulated bus).
  [[nodiscard]] std::span<capture::Tap* const> capture_taps() const noexcept {
    return capture_taps_;
  }
  void add_capture_tap(capture::Tap& tap) { capture_taps_.push_back(&tap); }

 protected:
  virtual void status_extra(nlohmann::json& j) const;

 private:
  std::vector<capture::Tap*> capture_taps_;
};

// Creates the configured bus kind; nullptr and `why_not` set when it cannot be created.
[[nodiscard]] std::unique_ptr<BusService> make_bus_service(const DaemonConfig& config,
                                                           std::string& why_not);

// Socket commands that belong to one bus kind: on another bus they answer "not_<kind>".
struct BusCommandSet {
  BusKind kind;
  std::string_view kind_name;
  std::span<const std::string_view> commands;
};
[[nodiscard]] std::span<const BusCommandSet> bus_commands() noexcept;

// The factories of the bus kinds (one file each).
[[nodiscard]] std::unique_ptr<BusService> make_simulated_service(const DaemonConfig& config,
                                                                 std::string& why_not);
[[nodiscard]] std::unique_ptr<BusService> make_powerlink_service(const DaemonConfig& config,
                                                                 std::string& why_not);
[[nodiscard]] std::unique_ptr<BusService> make_canio_service(const DaemonConfig& config,
                                                             std::string& why_not);

}  // namespace ds1928
