// Simulated EnDat 2.2 (or 2.1) encoder: the memory areas of endat.md §3–§5, write protection per
// area, processing times, and faults to inject. It speaks EnDat frames (endat/wire.hpp): one
// call per wire transaction, master frame in, reply frame out (empty = no start bit).
// Time-driven and single-threaded: the caller passes its notion of "now"; nothing here sleeps.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "endat/command.hpp"
#include "endat/ident.hpp"
#include "endat/wire.hpp"

namespace ds1928::sim {

struct EncoderArea {
  uint8_t words_per_block = 16;
  uint8_t blocks = 1;
  bool writable = false;
  std::vector<uint16_t> words;  // blocks × words_per_block
};

// Processing times the encoder reports after each transaction (endat.md §6), before `scale`.
struct EncoderTiming {
  int64_t select_memory_ns = 2'000'000;     // memory-area selection: real drivers wait 1–12 ms
  int64_t read_parameter_ns = 2'000'000;    // parameter transfer: 2–13 ms
  int64_t write_parameter_ns = 12'000'000;  // writing to EEPROM takes longest
  int64_t reset_ns = 50'000'000;            // after a reset the encoder is deaf this long
  int64_t error_reset_ns = 2'000'000;
  int64_t select_info_ns = 0;  // additional information follows with the next frame
  double scale = 1.0;          // tests scale every time down
};

struct EncoderFaults {
  double crc_error_rate = 0.0;   // probability that a reply frame gets one bit flipped
  uint32_t seed = 1;             // for the rate above: runs are reproducible
  bool position_error = false;   // operating status error bit 2 "position value" + F1
  bool battery_warning = false;  // warning bit 3 "battery charge low"
  bool battery_error = false;    // error bit 6 "battery change required"
  // Any further conditions by bit: operating status word 0 (EnDatError: 0 lighting, 1 signal
  // amplitude, 2 position, 3 overvoltage, 4 undervoltage, 5 overcurrent, 6 battery) and word 1
  // (EnDatWarning: 0 frequency collision, 1 temperature, 2 lighting reserve, 3 battery charge,
  // 4 reference point).
  uint16_t error_bits = 0;
  uint16_t warning_bits = 0;
};

struct EncoderDescription {
  endat::CommandSet command_set = endat::CommandSet::EnDat22;
  endat::EncoderType type = endat::EncoderType::Rotary;
  uint32_t steps_per_revolution = 1u << 25;
  uint16_t revolutions = 4096;  // 0 = singleturn
  uint32_t signal_periods = 2048;
  unsigned position_bits = 0;  // 0 = derived from steps and revolutions
  endat::IdNumber id_number{{'0', '2'}, 1080790};
  endat::SerialNumber serial_number{'S', 36845217, ' '};
  uint16_t version_word = 0;  // word 8; 0 = 0x0022 (2.2) or 0x0021 (2.1)
  uint16_t warnings_supported = 0x001F;
  double temperature_c = 41.5;           // additional information "temperature 1"
  double temperature2_c = 38.0;          // "temperature 2"
  std::map<uint8_t, EncoderArea> areas;  // by MRS code
  EncoderTiming timing;
  EncoderFaults faults;

  [[nodiscard]] unsigned effective_position_bits() const noexcept;
};

// A complete description: every area of endat.md §3 with its default size and protection, the
// manufacturer words computed from the identification fields, checksum in word 47.
[[nodiscard]] EncoderDescription default_encoder_description();

// Recomputes the manufacturer words (MRS 0xA1/0xA3/0xA5) from the identification fields, keeping
// words they do not cover, and the checksum word 47 (16-bit sum of words 0..47 is zero).
void apply_identification(EncoderDescription& d);

// An area of `blocks` × `words_per_block` zero words. (The YAML description file is read by
// sim/encoder_description_yaml.hpp.)
[[nodiscard]] EncoderArea make_encoder_area(uint8_t words_per_block, uint8_t blocks, bool writable);

// What one transaction did: the reply on the wire and how long the encoder needs before the
// next command (the module waits this long, as real firmware waits fixed delays).
struct EncoderResponse {
  endat::wire::BitFrame reply;
  int64_t processing_ns = 0;
};

class EnDatEncoder {
 public:
  explicit EnDatEncoder(EncoderDescription description = default_encoder_description());

  // One wire transaction at `now_ns`.
  [[nodiscard]] EncoderResponse transact(const endat::wire::BitFrame& master, int64_t now_ns);

  // Position in measuring steps, fed by the owner's motion profile (wraps to the position bits).
  void set_position(uint64_t steps) noexcept { position_ = steps & position_mask(); }
  [[nodiscard]] uint64_t position() const noexcept { return position_; }

  // Faults.
  void set_crc_error_rate(double p) noexcept { description_.faults.crc_error_rate = p; }
  void inject_crc_errors(unsigned next_replies) noexcept { forced_crc_errors_ = next_replies; }
  void set_position_error(bool on) noexcept { description_.faults.position_error = on; }
  void set_battery_warning(bool on) noexcept { description_.faults.battery_warning = on; }
  void set_battery_error(bool on) noexcept { description_.faults.battery_error = on; }
  // Conditions by bit of the error and warning words. A condition sets its bits at once and again
  // after every clear while it lasts; a condition that ends leaves its bits set until the master
  // clears them (error reset or writing the word), as an encoder's status words behave.
  void set_error_conditions(uint16_t bits) noexcept;
  void set_warning_conditions(uint16_t bits) noexcept;
  // Additional information a test can move: the temperatures (°C) and position value 2 (MRS
  // 0x42–0x44; unset, it follows the position).
  void set_temperature_c(double c) noexcept { description_.temperature_c = c; }
  void set_temperature2_c(double c) noexcept { description_.temperature2_c = c; }
  void set_position2(std::optional<uint64_t> steps) noexcept { position2_ = steps; }
  // The data word of additional information `code` (0x41..0x5E) as the next frame would carry it.
  [[nodiscard]] uint16_t additional_info(uint8_t code) const { return info_data(code); }
  // The next `n` transactions get no answer (cable unplugged).
  void inject_no_response(unsigned n) noexcept { forced_silence_ = n; }

  // Direct memory access for tests and diagnostics (no wire, no protection).
  [[nodiscard]] std::optional<uint16_t> word(uint8_t mrs, uint8_t block, uint8_t param) const;
  bool set_word(uint8_t mrs, uint8_t block, uint8_t param, uint16_t value);

  [[nodiscard]] const EncoderDescription& description() const noexcept { return description_; }
  [[nodiscard]] endat::CommandSet command_set() const noexcept { return description_.command_set; }
  [[nodiscard]] unsigned position_bits() const noexcept { return position_bits_; }
  [[nodiscard]] uint16_t error_word() const;    // operating status word 0
  [[nodiscard]] uint16_t warning_word() const;  // operating status word 1
  [[nodiscard]] uint64_t transactions() const noexcept { return transactions_; }
  [[nodiscard]] uint64_t corrupted_replies() const noexcept { return corrupted_; }

 private:
  struct Selection {
    uint8_t mrs = 0;
    uint8_t block = 0;
  };
  struct InfoSelection {
    uint8_t code = 0;  // 0x41..0x4E / 0x51..0x5E
    unsigned busy_frames = 0;
  };

  [[nodiscard]] uint64_t position_mask() const noexcept;
  [[nodiscard]] int64_t scaled(int64_t ns) const noexcept;
  void apply_conditions();
  uint16_t* status_word(unsigned index);
  [[nodiscard]] std::optional<endat::wire::AdditionalInfo> next_info(
      std::optional<InfoSelection>& sel, uint64_t frame_index);
  [[nodiscard]] uint16_t info_data(uint8_t code) const;
  [[nodiscard]] endat::wire::BitFrame position_frame(bool endat22);
  void finish(endat::wire::BitFrame& reply);
  void reset_state();

  EncoderDescription description_;
  unsigned position_bits_ = 0;
  uint64_t position_ = 0;
  std::optional<uint64_t> position2_;
  std::optional<Selection> selection_;
  std::optional<InfoSelection> ai1_;
  std::optional<InfoSelection> ai2_;
  int64_t deaf_until_ns_ = INT64_MIN;
  unsigned forced_crc_errors_ = 0;
  unsigned forced_silence_ = 0;
  std::mt19937 rng_;
  uint64_t transactions_ = 0;
  uint64_t corrupted_ = 0;
  uint64_t frames_ = 0;
};

}  // namespace ds1928::sim
