// A simulated cyclic bus for one direction that delivers, drops, delays or repeats the register
// image of each cycle. Like X2X and POWERLINK it keeps the last valid values: the receiver
// always sees some image the sender wrote, never a torn one, and never one older than an image
// it has already seen (a late image that is overtaken is discarded, as a stale frame would be).
#pragma once

#include <cstdint>
#include <vector>

namespace ds1928::flatstream::test {

enum class BusEvent : uint8_t { Deliver, Drop, Delay, Repeat };

template <typename Frame>
class LossyLink {
 public:
  // The sender wrote `f` in cycle `t`; what happens to it is `e` (delay: `k` cycles).
  void write(const Frame& f, uint64_t t, BusEvent e, unsigned k = 0) {
    switch (e) {
      case BusEvent::Deliver:
        pipe_.push_back({t, t, f});
        break;
      case BusEvent::Drop:
        break;
      case BusEvent::Delay:
        pipe_.push_back({t, t + k, f});
        break;
      case BusEvent::Repeat:
        // The receiver gets the previous cycle's registers again; this image comes one later.
        freeze_ = true;
        pipe_.push_back({t, t + 1, f});
        break;
    }
  }
  // What the receiver sees in cycle `t`.
  const Frame& read(uint64_t t) {
    if (freeze_) {
      freeze_ = false;
      return view_;
    }
    for (std::size_t i = 0; i < pipe_.size();) {
      if (pipe_[i].arrive <= t) {
        if (!seen_ || pipe_[i].written >= view_written_) {
          view_ = pipe_[i].frame;
          view_written_ = pipe_[i].written;
          seen_ = true;
        }
        pipe_[i] = pipe_.back();
        pipe_.pop_back();
      } else {
        ++i;
      }
    }
    return view_;
  }

 private:
  struct InFlight {
    uint64_t written;
    uint64_t arrive;
    Frame frame;
  };
  std::vector<InFlight> pipe_;
  Frame view_{};
  uint64_t view_written_ = 0;
  bool seen_ = false;
  bool freeze_ = false;
};

}  // namespace ds1928::flatstream::test
