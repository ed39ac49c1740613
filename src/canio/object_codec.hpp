// The cyclic CAN objects of one X20DS1928 in function model 254 (datasheet §11.3.2, offsets from
// the object dictionary): two 8-byte input objects (module → master) and one output object
// (master → module).
//   input object 1: PositionHW 0–3, PositionLW 4–7
//   input object 2: InputSequence 0, RxByte1–5 1–5, ErrorInfo 6, PosCycle 7   (datasheet 8–15)
//   output object:  OutputSequence 0, TxByte1–5 1–5, AckErrorInfo 6, byte 7 unused (0)
// Multi-byte registers in the configured byte order (the datasheet does not state it; CANopen
// and X2X are little endian, the default). Pure: no I/O, no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "x20ds1928/module_image.hpp"

namespace ds1928::canio {

enum class ByteOrder : uint8_t { Little, Big };

inline constexpr std::size_t kObjectBytes = 8;
using CanObject = std::array<uint8_t, kObjectBytes>;

// Which of the module's objects a frame carries.
enum class ObjectKind : uint8_t { Position = 0, Status = 1, Output = 2 };

// Module side (simulator): the inputs as the two objects.
void pack_position_object(const ModuleInputs& in, ByteOrder order, CanObject& out) noexcept;
void pack_status_object(const ModuleInputs& in, CanObject& out) noexcept;
// Master side: fills the fields the object carries, leaves the others alone. False (nothing
// written) when `bytes` is not exactly 8 bytes long.
[[nodiscard]] bool unpack_position_object(std::span<const uint8_t> bytes, ByteOrder order,
                                          ModuleInputs& in) noexcept;
[[nodiscard]] bool unpack_status_object(std::span<const uint8_t> bytes, ModuleInputs& in) noexcept;

// Master side: the output object (Tx bytes past the fifth are not carried).
void pack_output_object(const ModuleOutputs& out, CanObject& bytes) noexcept;
// Module side. False when `bytes` is shorter than the 7 used bytes or longer than 8.
[[nodiscard]] bool unpack_output_object(std::span<const uint8_t> bytes,
                                        ModuleOutputs& out) noexcept;

}  // namespace ds1928::canio
