// The daemon's side of the CAN-I/O bus: opens the ports (SocketCAN, or the cross-process virtual
// test bus when canio.virtual_bus is set), checks the interface's bit rate, and contributes the
// CAN state, counters and per-node figures to `status`, the log and the metrics
// (canio_metrics.cpp). Same shape as every bus kind: <kind>_service.hpp/.cpp + <kind>_metrics.cpp.
#pragma once

#include <memory>
#include <vector>

#include "bus_service.hpp"
#include "can/virtual_bus.hpp"
#include "canio/canio_bus.hpp"

namespace ds1928 {

class CanioService final : public BusService {
 public:
  // Owns the bus; `vbus` (the virtual test bus, or nullptr) outlives its ports.
  CanioService(std::unique_ptr<canio::CanioBus> bus, std::shared_ptr<canio::VirtualCanBus> vbus)
      : vbus_(std::move(vbus)), bus_(std::move(bus)) {}

  [[nodiscard]] BusDriver& driver() noexcept override { return *bus_; }
  [[nodiscard]] std::string start_detail() const override { return bus_->start_error(); }
  // On a working controller: "operational" while every node answers, "degraded" while some do,
  // "no_nodes" while none does, the nodes' last errors as the cause.
  [[nodiscard]] Reported reported_state() const override;
  [[nodiscard]] std::string axis_cause(std::size_t axis) const override;
  // The axis' node: the NMT state of its last boot-up or heartbeat (canio/module_phase).
  [[nodiscard]] NodePhase node_phase(std::size_t axis) const override;
  void watch(std::vector<BusEvent>& events, bool first,
             std::chrono::steady_clock::time_point now) override;
  void append_metrics(metrics::Exposition& out) const override;  // canio_metrics.cpp

 protected:
  void status_extra(nlohmann::json& j) const override;

 private:
  void on_node_event(const canio::CanioNodeEvent& e, std::vector<BusEvent>& events);
  // Marks a node as heard (an answer, an event); true when it was not before.
  bool note_heard(uint8_t node);

  std::shared_ptr<canio::VirtualCanBus> vbus_;  // outlives the ports
  std::unique_ptr<canio::CanioBus> bus_;
  canio::CanState can_state_ = canio::CanState::Unknown;
  SaidCounter tx_full_;
  std::vector<bool> silent_;
  std::vector<bool> answered_;  // per axis: has delivered samples since the start
  std::vector<uint8_t> heard_;  // nodes heard from since the start
};

}  // namespace ds1928
