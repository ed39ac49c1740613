// EnDatAck through the module register: acknowledge (bit 0) and Rescan (bit 1), with the wait
// for the module to run them.
#include <boost/asio/steady_timer.hpp>

#include "endat_service_state.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {

void EnDatService::endat_ack_register(std::size_t index, uint8_t bits, AckDone done) {
  if (index >= axes_.size()) return done(make_error_code(EnDatServiceErrc::no_such_axis), false, 0);
  registers_.write(static_cast<uint16_t>(index), reg::kEnDatAck, 1, bits,
                   [this, index, bits, done = std::move(done), alive = std::weak_ptr<bool>(alive_)](
                       std::error_code ec, uint32_t) mutable {
                     if (alive.expired()) return;
                     if (ec) return done(ec, false, 0);
                     poll_endat_ack(index, bits, Clock::now() + kEnDatAckTimeout, 0,
                                    std::move(done));
                   });
}

void EnDatService::poll_endat_ack(std::size_t index, uint8_t bits, Clock::time_point deadline,
                                  unsigned reads, AckDone done) {
  registers_.read(
      static_cast<uint16_t>(index), reg::kEnDatAck, 1,
      [this, index, bits, deadline, reads, done = std::move(done),
       alive = std::weak_ptr<bool>(alive_)](std::error_code ec, uint32_t v) mutable {
        if (alive.expired()) return;
        if (ec) return done({}, false, reads + 1);  // written; completion not observable
        if ((v & bits) == 0) return done({}, true, reads + 1);
        if (Clock::now() >= deadline || !running_)
          return done(make_error_code(EnDatServiceErrc::timeout), false, reads + 1);
        auto timer = std::make_shared<boost::asio::steady_timer>(io_, std::chrono::milliseconds(5));
        timer->async_wait([this, index, bits, deadline, reads, timer, done = std::move(done),
                           alive](const boost::system::error_code& e) mutable {
          if (e || alive.expired()) return;
          poll_endat_ack(index, bits, deadline, reads + 1, std::move(done));
        });
      });
}

}  // namespace ds1928
