#include "can/bit_budget.hpp"

namespace ds1928::canio {
namespace {

// The stuffable part of a frame as a bit string, most significant first, with the CRC-15 kept
// as it goes (the CRC covers exactly the bits before it) and stuffing counted on the fly.
class BitWriter {
 public:
  void put(uint32_t value, int bits) noexcept {
    for (int i = bits - 1; i >= 0; --i) {
      const bool b = ((value >> i) & 1u) != 0;
      if (crc_open_) {
        const bool next = b != (((crc_ >> 14) & 1u) != 0);
        crc_ = static_cast<uint16_t>((crc_ << 1) & 0x7FFF);
        if (next) crc_ ^= 0x4599;
      }
      ++bits_;
      // CAN 2.0 §5: after five equal bits the transmitter inserts their complement; that stuff
      // bit is the first of the next run.
      if (run_ != 0 && b == run_value_) {
        ++run_;
      } else {
        run_value_ = b;
        run_ = 1;
      }
      if (run_ == 5) {
        ++stuff_;
        run_value_ = !b;
        run_ = 1;
      }
    }
  }
  void close_crc() noexcept { crc_open_ = false; }
  [[nodiscard]] uint16_t crc() const noexcept { return crc_; }
  [[nodiscard]] uint32_t bits() const noexcept { return bits_; }
  [[nodiscard]] uint32_t stuff() const noexcept { return stuff_; }

 private:
  uint16_t crc_ = 0;
  bool crc_open_ = true;
  bool run_value_ = false;
  uint32_t run_ = 0;
  uint32_t bits_ = 0;
  uint32_t stuff_ = 0;
};

}  // namespace

int64_t bits_to_ns(uint64_t bits, uint32_t bitrate) noexcept {
  if (bitrate == 0) return 0;
  // Rounded up: a budget must never look shorter than the bus needs.
  return static_cast<int64_t>((bits * 1'000'000'000ull + bitrate - 1) / bitrate);
}

FrameWire frame_wire(const CanFrame& f) noexcept {
  BitWriter w;
  const uint32_t dlc = f.dlc > 15 ? 15u : f.dlc;
  w.put(0, 1);  // SOF (dominant)
  if (f.extended) {
    const uint32_t id = f.id & kMaxExtendedId;
    w.put(id >> 18, 11);  // base identifier
    w.put(1, 1);          // SRR (recessive)
    w.put(1, 1);          // IDE (recessive: extended)
    w.put(id & 0x3FFFF, 18);
    w.put(f.rtr ? 1 : 0, 1);
    w.put(0, 2);  // r1, r0
  } else {
    w.put(f.id & kMaxStandardId, 11);
    w.put(f.rtr ? 1 : 0, 1);
    w.put(0, 1);  // IDE (dominant: standard)
    w.put(0, 1);  // r0
  }
  w.put(dlc, 4);
  // A DLC of 9..15 still means 8 bytes in classic CAN; a remote frame carries none.
  const uint32_t bytes = f.rtr ? 0u : (dlc > 8 ? 8u : dlc);
  for (uint32_t i = 0; i < bytes; ++i) w.put(f.data[i], 8);
  w.close_crc();
  const uint16_t crc = w.crc();
  w.put(crc, 15);
  FrameWire r;
  r.stuffable = w.bits();
  r.stuff = w.stuff();
  r.total = r.stuffable + r.stuff + kUnstuffedTailBits;
  r.crc = crc;
  return r;
}

uint32_t frame_wire_bits(const CanFrame& frame) noexcept {
  return frame_wire(frame).total;
}

CycleBudget cycle_budget(const CycleLoad& load) noexcept {
  CycleBudget b;
  const FrameBits in = frame_bits(load.input_bytes, load.extended_ids);
  const FrameBits out = frame_bits(load.output_bytes, load.extended_ids);
  const uint64_t n_in = uint64_t{load.modules} * load.input_frames_per_module;
  const uint64_t n_out = uint64_t{load.modules} * load.output_frames_per_module;
  b.frames = static_cast<uint32_t>(n_in + n_out);
  b.bits_nominal = n_in * in.nominal + n_out * out.nominal;
  b.bits_worst_case = n_in * in.worst_case + n_out * out.worst_case;
  if (load.sync) {
    // SYNC uses a standard identifier (0x080) whatever the objects use.
    const FrameBits s = frame_bits(load.sync_bytes, false);
    ++b.frames;
    b.bits_nominal += s.nominal;
    b.bits_worst_case += s.worst_case;
  }
  b.time_nominal_ns = bits_to_ns(b.bits_nominal, load.bitrate);
  b.time_worst_case_ns = bits_to_ns(b.bits_worst_case, load.bitrate);
  return b;
}

CycleFit check_cycle(const CycleLoad& load, int64_t period_ns) noexcept {
  CycleFit f;
  f.budget = cycle_budget(load);
  f.fits = period_ns > 0 && f.budget.time_worst_case_ns <= period_ns;
  f.fits_nominal = period_ns > 0 && f.budget.time_nominal_ns <= period_ns;
  f.margin_ns = period_ns - f.budget.time_worst_case_ns;
  if (period_ns > 0) {
    f.load_worst_case =
        static_cast<double>(f.budget.time_worst_case_ns) / static_cast<double>(period_ns);
    f.load_nominal = static_cast<double>(f.budget.time_nominal_ns) / static_cast<double>(period_ns);
  }
  return f;
}

}  // namespace ds1928::canio
