// The expected topology (docs/operations.md "Expected topology"): per axis the encoder the
// configuration expects (axes[].expected_encoder), per POWERLINK CN its identity (powerlink.nodes[]
// vendor_id, product_code, revision_no, serial_no — checked by the MN, docs/powerlink.md), per
// CAN-I/O node its identity object (canio.nodes[], checked by the driver, docs/canio.md), set
// against what the bus reports. An axis whose encoder differs stays bus_down with the reason
// (topology.on_mismatch: refuse, the default; warn: logged only), so a swapped cable or a
// replaced encoder never delivers positions under the wrong axis' name. Normal thread.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <system_error>
#include <vector>

#include "config/config.hpp"
#include "cycle_work.hpp"
#include "endat/ident.hpp"
#include "metrics/exposition.hpp"

namespace ds1928 {

class EnDatService;

// What differs between the expected encoder and the identified one ("serial_number: expected
// 'S1', found 'S36845217'"); empty: as expected. Pure.
[[nodiscard]] std::vector<std::string> encoder_differences(const ExpectedEncoder& expected,
                                                           const endat::Identification& found);
[[nodiscard]] std::string_view to_string(IdentityState s) noexcept;

class Topology {
 public:
  Topology(const DaemonConfig& config, CycleWork& work);

  // The EnDat service identified axis `axis` (or failed to): compare, set the axis' identity
  // state for the cycle, log. `found` nullptr when the identification failed.
  void on_identified(std::size_t axis, std::error_code error, const endat::Identification* found);

  // Why the axis is held down ("" when it is not).
  [[nodiscard]] std::string reason(std::size_t axis) const;
  // `ds1928ctl topology`: per axis expected and found, per POWERLINK CN and per CAN-I/O node
  // expected and found (`bus_status`: the bus' status_json(), whose nodes carry what the MN saw,
  // whose canopen_nodes carry the identity the CAN-I/O driver read).
  [[nodiscard]] nlohmann::json topology_json(const EnDatService* endat,
                                             const nlohmann::json& bus_status) const;
  void append_metrics(metrics::Exposition& out) const;

 private:
  const DaemonConfig& config_;
  CycleWork& work_;
  std::vector<std::string> differences_;  // per axis, joined
};

}  // namespace ds1928
