// The daemon's side of the POWERLINK bus: status (MN state, counters, per CN), the pl-* socket
// commands and the log lines about CNs reset or booted by the MN.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bus_service.hpp"
#include "config/powerlink_budget.hpp"
#include "powerlink/powerlink_bus.hpp"

namespace ds1928 {

class PowerlinkService final : public BusService {
 public:
  // Owns the bus.
  explicit PowerlinkService(std::unique_ptr<powerlink::PowerlinkBus> bus);
  // Borrows a bus that outlives the service (tests driving a PowerlinkBus themselves).
  explicit PowerlinkService(powerlink::PowerlinkBus& bus);

  [[nodiscard]] BusDriver& driver() noexcept override { return bus_; }
  // "waiting_for_link" while the interface has no carrier (named, with the fix); "booting" with
  // the CNs not yet operational.
  [[nodiscard]] Reported reported_state() const override;
  // The axis' CN: the MN's boot step and the NMT state the CN reported (powerlink/module_phase).
  [[nodiscard]] NodePhase node_phase(std::size_t axis) const override;
  // The interface's name, for the causes (set by the factory).
  void set_interface(std::string name) { interface_ = std::move(name); }
  // The configuration's cycle budget (nominal and worst case), shown in status and metrics.
  void set_cycle_budget(const PowerlinkCycleBudget& budget, uint16_t async_mtu) {
    budget_ = budget;
    async_mtu_ = async_mtu;
  }
  void register_commands(control::Server& server, const SocketConfig& socket) override;
  void watch(std::vector<BusEvent>& events, bool first,
             std::chrono::steady_clock::time_point now) override;
  void append_metrics(metrics::Exposition& out) const override;  // powerlink_metrics.cpp

 protected:
  void status_extra(nlohmann::json& j) const override;

 private:
  struct NodeSeen {
    uint32_t resets = 0;
    uint32_t boots = 0;
    uint32_t object_failures = 0;
    uint32_t error_entries = 0;  // CnStatus::status_error_entries said
    powerlink::ImageSource image = powerlink::ImageSource::kPacked;  // said
    bool errsig_gave_up_said = false;  // "no error signalling" is said once per node
    bool prc_fallback_said = false;    // "polled with PReq/PRes instead of PRC", once per node
    SaidCounter late_pres;
    SaidCounter nmt_refused;
  };
  std::unique_ptr<powerlink::PowerlinkBus> owned_;
  powerlink::PowerlinkBus& bus_;
  SaidCounter cycle_time_exceeded_;
  std::vector<NodeSeen> nodes_;
  std::string interface_;
  std::optional<PowerlinkCycleBudget> budget_;
  uint16_t async_mtu_ = 300;
};

}  // namespace ds1928
