// A CN's process image from its PDO mapping (EPSG DS 301: 0x1A00 TPDO → PRes, 0x1600 RPDO →
// PReq; each entry says which object, at which bit offset, how many bits). The entries name
// objects of the bus controller; which object holds which register of which slot is the bus
// controller's object scheme (ObjectScheme below: data, not code; its default is an assumption,
// docs/powerlink.md §Process image from the PDO mapping). Binding the entries through the scheme
// gives each module's register offsets (ModuleMapping::fields), which read_inputs()/
// write_outputs() then use instead of the packed block.
// Pure: no I/O; bind_pdo_mapping() runs at start, never on the cycle path.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/fixed_text.hpp"
#include "powerlink/concise_dcf.hpp"
#include "powerlink/cycle_budget.hpp"
#include "powerlink/powerlink_options.hpp"
#include "powerlink/process_image.hpp"
#include "powerlink/standard_objects.hpp"

namespace ds1928::powerlink {

// The registers of an X20DS1928 (function model 0) a PDO carries, and their sub-index in the
// slot's object (the scheme's table).
struct SchemeRegister {
  ImageField field;
  uint8_t subindex;
  uint8_t bytes;
  std::string_view name;
};
// Inputs object of a slot: sub 1..7 the fixed registers, 8.. RxByte1..27. Outputs object: sub 1
// OutputSequence, 2 AckErrorInfo, 3.. TxByte1..27.
inline constexpr std::array<SchemeRegister, 7> kSchemeInputs{{
    {ImageField::kPositionHW, 1, 4, "PositionHW"},
    {ImageField::kPositionLW, 2, 4, "PositionLW"},
    {ImageField::kPosTime, 3, 4, "PosTime"},
    {ImageField::kPosCycle, 4, 1, "PosCycle"},
    {ImageField::kSdcLifeCount, 5, 1, "SDCLifeCount"},
    {ImageField::kErrorInfo, 6, 1, "ErrorInfo"},
    {ImageField::kInputSequence, 7, 1, "InputSequence"},
}};
inline constexpr uint8_t kSchemeRxByteFirstSub = 8;
// Optional inputs, taken when the mapping carries them (never required, not in the packed
// block): EnDatInfoOK and EnDatInfo01..04, after the last RxByte's sub-index (8 + 27 = 35).
inline constexpr std::array<SchemeRegister, 5> kSchemeInfoInputs{{
    {ImageField::kInfoOk, 0x30, 1, "EnDatInfoOK"},
    {ImageField::kInfo1, 0x31, 2, "EnDatInfo01"},
    {ImageField::kInfo2, 0x32, 2, "EnDatInfo02"},
    {ImageField::kInfo3, 0x33, 2, "EnDatInfo03"},
    {ImageField::kInfo4, 0x34, 2, "EnDatInfo04"},
}};
static_assert(kSchemeInfoInputs[0].subindex >= kSchemeRxByteFirstSub + kMaxFlatstreamMtu);
inline constexpr std::array<SchemeRegister, 2> kSchemeOutputs{{
    {ImageField::kOutputSequence, 1, 1, "OutputSequence"},
    {ImageField::kAckErrorInfo, 2, 1, "AckErrorInfo"},
}};
inline constexpr uint8_t kSchemeTxByteFirstSub = 3;

// The bus controller's object scheme: the inputs of the module in slot s are object
// input_index + s, its outputs output_index + s (sub-indices: the tables above).
using ObjectScheme = PdoObjectScheme;

// Why bind_pdo_mapping() refused. `what` names the node's entry or the axis and register.
struct PdoBindIssue {
  std::error_code error;
  FixedText<128> what;  // fixed: the MN binds a mapping it read on the cycle thread
  uint8_t slot = 0;     // kPdoRegisterNotMapped: the module missing it
};

struct PdoMappingLists {
  std::span<const PdoMapEntry> tpdo;         // 0x1A00/1..n: the PRes
  std::span<const PdoMapEntry> rpdo;         // 0x1600/1..n: the PReq
  uint16_t tpdo_index = obj::kTxPdoMapping;  // for messages
  uint16_t rpdo_index = obj::kRxPdoMapping;
  // Only the outputs are bound (the RPDO of the PResMN a chained CN reads): no input is needed.
  bool outputs_only = false;
};

// The layout of one CN's modules from its mapping. Each module needs PositionHW, PositionLW,
// PosTime, PosCycle and ErrorInfo; with an input MTU InputSequence and RxByte1..MTU; with an
// output MTU OutputSequence, TxByte1..MTU and AckErrorInfo. Refused: an entry whose length is no
// whole number of bytes or differs from its register's, or whose offset is no whole byte or ends
// past kMaxIsoPayload (MnError::kPdoMappingEntryInvalid, naming 0x1A00/k and the object); a
// module missing a register (MnError::kPdoRegisterNotMapped, naming the slot and register).
// Entries of objects outside the scheme (other modules of the bus controller) are left alone.
// Allocates nothing, refusal included (the MN binds on the cycle thread).
[[nodiscard]] std::optional<NodeImageLayout> bind_pdo_mapping(const PdoMappingLists& lists,
                                                              const ObjectScheme& scheme,
                                                              std::span<const ModuleSpec> modules,
                                                              PdoBindIssue& issue) noexcept;

// The mapping entries of `mapping_index` (sub 0 = count) in an object list; nullopt when the
// list does not write sub 0.
[[nodiscard]] std::optional<std::vector<PdoMapEntry>> mapping_from_objects(
    std::span<const CdcEntry> objects, uint16_t mapping_index);

// The mapping the scheme gives for `layout` (the packed or offset layout): what a bus controller
// with these modules would report; the simulator serves it and tests build rearranged ones.
[[nodiscard]] std::vector<PdoMapEntry> tpdo_mapping_of(const NodeImageLayout& layout,
                                                       const ObjectScheme& scheme);
// The RPDO entries of the layout's outputs, `base` bytes further on: with base 0 the PReq's,
// else where the MN places a chained node's outputs in the PResMN (pres_mn_outputs()).
[[nodiscard]] std::vector<PdoMapEntry> rpdo_mapping_of(const NodeImageLayout& layout,
                                                       const ObjectScheme& scheme,
                                                       uint16_t base = 0);

// Where a chained node's outputs go in the PResMN: place_pres_mn_outputs() (cycle_budget.hpp).

}  // namespace ds1928::powerlink
