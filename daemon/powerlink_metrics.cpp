// The POWERLINK bus' metric families (OpenMetrics endpoint): MN counters, and per CN (label
// node) its NMT state, PRes received/lost/late/stale, the PRes latency histogram, resets, boots
// and SDO errors. Read from the status snapshot the cycle thread publishes and the per-CN
// latency histograms it writes (powerlink_bus.hpp).
#include <array>
#include <string>
#include <vector>

#include "powerlink_service.hpp"

namespace ds1928 {

using metrics::Type;

void PowerlinkService::append_metrics(metrics::Exposition& out) const {
  const auto st = bus_.status();
  const auto& mc = st.counters;
  out.family("ds1928_powerlink_cycle_time_exceeded", Type::Counter,
             "POWERLINK cycles whose exchange took longer than the period.");
  out.sample(static_cast<uint64_t>(mc.cycle_time_exceeded.events));
  out.family("ds1928_powerlink_invalid_frames", Type::Counter,
             "Frames the POWERLINK codec rejected.");
  out.sample(static_cast<uint64_t>(mc.invalid_frames));
  out.family("ds1928_powerlink_unexpected_frames", Type::Counter,
             "POWERLINK frames that fit no expected slot.");
  out.sample(static_cast<uint64_t>(mc.unexpected_frames));
  out.family("ds1928_powerlink_foreign_mn_frames", Type::Counter,
             "SoC, PReq or SoA frames of another Managing Node on the segment.");
  out.sample(static_cast<uint64_t>(mc.foreign_mn_frames));
  out.family("ds1928_powerlink_async_timeouts", Type::Counter,
             "IdentRequests/StatusRequests without their answer within async_timeout.");
  out.sample(static_cast<uint64_t>(mc.async_timeouts));

  if (budget_) {
    out.family("ds1928_powerlink_cycle_budget_seconds", Type::Gauge,
               "The POWERLINK cycle on the wire by the configuration: nominal (each CN at its "
               "expected latency) and worst (each CN at its PRes timeout).",
               "seconds");
    out.sample({{"case", "nominal"}}, budget_->nominal.total_us() / 1e6);
    out.sample({{"case", "worst"}}, budget_->worst.total_us() / 1e6);
    out.family("ds1928_powerlink_cycle_budget_worst_fits", Type::Gauge,
               "1 when the worst-case POWERLINK cycle fits the period, 0 when a CN answering at "
               "its timeout overruns it.");
    out.sample(uint64_t{budget_->worst_fits() ? 1u : 0u});
  }
  std::vector<std::string> node(st.node_count);
  for (std::size_t i = 0; i < st.node_count; ++i) node[i] = std::to_string(st.nodes[i].node);

  static constexpr std::array kStates{powerlink::NmtState::kOff,
                                      powerlink::NmtState::kInitialising,
                                      powerlink::NmtState::kResetApplication,
                                      powerlink::NmtState::kResetCommunication,
                                      powerlink::NmtState::kResetConfiguration,
                                      powerlink::NmtState::kNotActive,
                                      powerlink::NmtState::kPreOperational1,
                                      powerlink::NmtState::kPreOperational2,
                                      powerlink::NmtState::kReadyToOperate,
                                      powerlink::NmtState::kOperational,
                                      powerlink::NmtState::kStopped,
                                      powerlink::NmtState::kBasicEthernet};
  out.family("ds1928_powerlink_cn_nmt_state", Type::Gauge,
             "NMT state a CN last reported: 1 for the current state.");
  for (std::size_t i = 0; i < st.node_count; ++i)
    for (auto s : kStates)
      out.sample({{"node", node[i]}, {"state", powerlink::to_string(s)}},
                 uint64_t{st.nodes[i].nmt == s ? 1u : 0u});

  const auto per_node = [&](std::string_view name, std::string_view help, auto value) {
    out.family(name, Type::Counter, help);
    for (std::size_t i = 0; i < st.node_count; ++i)
      out.sample({{"node", node[i]}}, static_cast<uint64_t>(value(st.nodes[i])));
  };
  using Cn = powerlink::CnStatus;
  per_node("ds1928_powerlink_pres_received", "PRes frames received from the CN.",
           [](const Cn& n) { return n.pres_received; });
  per_node("ds1928_powerlink_pres_lost", "PReqs the CN did not answer within its PRes timeout.",
           [](const Cn& n) { return n.loss_of_pres.events; });
  per_node("ds1928_powerlink_pres_late", "PRes received after the PRes timeout.",
           [](const Cn& n) { return n.late_pres.events; });
  per_node("ds1928_powerlink_pres_stale", "Late PRes of an earlier PReq, dropped.",
           [](const Cn& n) { return n.stale_pres_dropped; });
  per_node("ds1928_powerlink_pres_not_ready",
           "PRes with RD = 0 from an OPERATIONAL CN: data not ready, not taken as inputs.",
           [](const Cn& n) { return n.pres_not_ready; });
  per_node("ds1928_powerlink_cn_resets", "NMTResetNode commands the MN sent to the CN.",
           [](const Cn& n) { return n.resets; });
  per_node("ds1928_powerlink_cn_boots", "Times the CN reached OPERATIONAL.",
           [](const Cn& n) { return n.boots; });
  per_node("ds1928_powerlink_sdo_errors", "SDO transfers to the CN that failed.",
           [](const Cn& n) { return n.sdo_errors; });
  per_node("ds1928_powerlink_configuration_failures",
           "Objects of the CN's configuration it refused.",
           [](const Cn& n) { return n.object_failures; });

  out.family("ds1928_powerlink_pres_latency_seconds", Type::Histogram,
             "PReq sent to the CN until its PRes received.", "seconds");
  for (std::size_t i = 0; i < st.node_count; ++i) {
    const powerlink::PresLatencyHistogram* h = bus_.pres_latency(st.nodes[i].node);
    if (!h) continue;
    constexpr std::size_t N = powerlink::PresLatencyHistogram::N;
    std::array<double, N> upper{};
    std::array<uint64_t, N + 1> counts{};
    for (std::size_t k = 0; k < N; ++k) upper[k] = static_cast<double>(h->upper_ns()[k]) / 1e9;
    for (std::size_t k = 0; k <= N; ++k) counts[k] = h->bucket(k);
    out.histogram({{"node", node[i]}}, upper, counts, static_cast<double>(h->sum_ns()) / 1e9);
  }
}

}  // namespace ds1928
