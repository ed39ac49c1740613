#include "endat_service_state.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// EnDatError / EnDatWarning every second

void EnDatService::arm_status() {
  if (!running_) return;
  status_timer_.expires_after(std::chrono::seconds(1));
  status_timer_.async_wait(
      [this, alive = std::weak_ptr<bool>(alive_)](const boost::system::error_code& ec) {
        if (ec || alive.expired()) return;
        read_status_registers();
        arm_status();
      });
}

void EnDatService::read_status_registers() {
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    Axis& a = *axes_[i];
    if (a.status_pending != 0) continue;  // the previous read has not come back yet
    a.status_pending = 2;
    for (const uint16_t reg : {reg::kEnDatError, reg::kEnDatWarning}) {
      registers_.read(
          static_cast<uint16_t>(i), reg, 2,
          [this, i, reg, alive = std::weak_ptr<bool>(alive_)](std::error_code ec, uint32_t v) {
            if (alive.expired()) return;
            Axis& ax = *axes_[i];
            if (ax.status_pending > 0) --ax.status_pending;
            ax.status_error = ec;
            if (ec) return;
            const auto word = static_cast<uint16_t>(v);
            auto& counters = work_.counters(i);
            if (reg == reg::kEnDatError) {
              ax.endat_error = word;
              counters.endat_error.store(word, std::memory_order_relaxed);
            } else {
              ax.endat_warning = word;
              counters.endat_warning.store(word, std::memory_order_relaxed);
            }
          });
    }
  }
}

}  // namespace ds1928
