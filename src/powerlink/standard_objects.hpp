// POWERLINK's standard objects (EPSG DS 301) that the product reads, writes or serves: the one
// table of them. The MN (identity check, cycle objects), the concise DCF import (the MN's per-node
// lists, PDO mappings, cycle timing) and the simulated CN's object dictionary (a generic read and
// write over the rows a CN holds) all name an object through it; no index is typed elsewhere.
// Names as DS 301 / openCONFIGURATOR's XDD spell them. Pure data, constexpr.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace ds1928::powerlink {

// Object indices (the rows below give sub-indices, types and access).
namespace obj {
inline constexpr uint16_t kDeviceType = 0x1000;
inline constexpr uint16_t kErrorRegister = 0x1001;
inline constexpr uint16_t kCycleLen = 0x1006;
inline constexpr uint16_t kStoreParam = 0x1010;
inline constexpr uint16_t kRestoreDefParam = 0x1011;
inline constexpr uint16_t kIdentity = 0x1018;
inline constexpr uint16_t kVerifyConfiguration = 0x1020;
inline constexpr uint16_t kRxPdoComm = 0x1400;
inline constexpr uint16_t kRxPdoMapping = 0x1600;
// The second RPDO channel: a PollResponse Chaining node's outputs from the PResMN (its NodeID_U8
// names the MN, EPSG DS 302-C), beside channel 0 for the PReq.
inline constexpr uint16_t kRxPdoCommPresMn = 0x1401;
inline constexpr uint16_t kRxPdoMappingPresMn = 0x1601;
inline constexpr uint16_t kTxPdoComm = 0x1800;
inline constexpr uint16_t kTxPdoMapping = 0x1A00;
inline constexpr uint16_t kMnCycTimeExceed = 0x1C02;
inline constexpr uint16_t kMnCnLossPResThreshold = 0x1C09;
inline constexpr uint16_t kCnLossSoc = 0x1C0B;
inline constexpr uint16_t kCnLossSoa = 0x1C0C;
inline constexpr uint16_t kCnLossPReq = 0x1C0D;
inline constexpr uint16_t kCnCrcError = 0x1C0F;
inline constexpr uint16_t kLossOfSocTolerance = 0x1C14;
inline constexpr uint16_t kConciseDcfList = 0x1F22;
inline constexpr uint16_t kExpConfDateList = 0x1F26;
inline constexpr uint16_t kExpConfTimeList = 0x1F27;
inline constexpr uint16_t kNodeAssignment = 0x1F81;
inline constexpr uint16_t kMnDeviceTypeIdList = 0x1F84;
inline constexpr uint16_t kMnVendorIdList = 0x1F85;
inline constexpr uint16_t kMnProductCodeList = 0x1F86;
inline constexpr uint16_t kMnRevisionNoList = 0x1F87;
inline constexpr uint16_t kMnSerialNoList = 0x1F88;
inline constexpr uint16_t kMnBootTime = 0x1F89;
inline constexpr uint16_t kMnCycleTiming = 0x1F8A;
inline constexpr uint16_t kMnPReqPayloadLimitList = 0x1F8B;
inline constexpr uint16_t kPResPayloadLimitList = 0x1F8D;
inline constexpr uint16_t kMnCnPResTimeout = 0x1F92;
inline constexpr uint16_t kCycleTiming = 0x1F98;
inline constexpr uint16_t kMultiplCycleAssign = 0x1F9B;

// Sub-indices with a meaning of their own.
inline constexpr uint8_t kCycleTimingPReqActPayload = 4;   // kCycleTiming/4
inline constexpr uint8_t kCycleTimingPResActPayload = 5;   // kCycleTiming/5
inline constexpr uint8_t kCycleTimingMultiplCycleCnt = 7;  // kCycleTiming/7
inline constexpr uint8_t kCycleTimingAsyncMtu = 8;         // kCycleTiming/8
// NMT_NodeAssignment bit 14: the node is polled by PollResponse Chaining.
inline constexpr uint32_t kNodeAssignmentPrc = 0x00004000;
// NMT_NodeAssignment bit 9: the node is polled in a multiplexed slot.
inline constexpr uint32_t kNodeAssignmentMultiplexed = 0x00000200;
// NMT_NodeAssignment bit 3: the MN does not go OPERATIONAL without the node.
inline constexpr uint32_t kNodeAssignmentMandatory = 0x00000008;
// NMT_NodeAssignment bit 8: the node is served in the asynchronous phase only, never polled.
inline constexpr uint32_t kNodeAssignmentAsyncOnly = 0x00000100;
// NMT_NodeAssignment bit 0: the entry describes a node.
inline constexpr uint32_t kNodeAssignmentExists = 0x00000001;
}  // namespace obj

enum class ObjType : uint8_t { kU8, kU16, kU32, kU64, kDomain };
enum class ObjAccess : uint8_t {
  kConst,  // fixed by the device (NumberOfEntries, limits)
  kRo,     // the device's own value (identity, counters): an SDO write is refused
  kRw,     // written by an MN's configuration manager
};
enum class ObjHolder : uint8_t {
  kCn,  // a CN's object: the simulated CN serves it
  kMn,  // the MN's own object (per-node lists in the MN's concise DCF)
};

struct StandardObject {
  uint16_t index = 0;
  uint8_t sub_first = 0;  // the sub-index, or the first of an array's entries
  uint8_t sub_last = 0;   // == sub_first but for arrays (PDO mappings, per-node lists)
  std::string_view name;  // DS 301 name (record.entry)
  ObjType type = ObjType::kU32;
  ObjAccess access = ObjAccess::kRw;
  ObjHolder holder = ObjHolder::kCn;
  uint64_t default_value = 0;
  std::string_view meaning;
};

[[nodiscard]] constexpr std::size_t type_size(ObjType t) noexcept {
  switch (t) {
    case ObjType::kU8:
      return 1;
    case ObjType::kU16:
      return 2;
    case ObjType::kU32:
      return 4;
    case ObjType::kU64:
      return 8;
    case ObjType::kDomain:
      return 0;
  }
  return 0;
}

namespace detail {
using enum ObjType;
using enum ObjAccess;
using enum ObjHolder;
using namespace obj;
// clang-format off
inline constexpr std::array kStandardObjects = std::to_array<StandardObject>({
  {kDeviceType, 0, 0, "NMT_DeviceType_U32", kU32, kRo, kCn, 0, "device type"},
  {kErrorRegister, 0, 0, "ERR_ErrorRegister_U8", kU8, kRo, kCn, 0, "error register (byte 0 of the static error bit field)"},
  {kCycleLen, 0, 0, "NMT_CycleLen_U32", kU32, kRw, kCn, 0, "cycle length, µs"},
  {kStoreParam, 0, 0, "NMT_StoreParam_REC.NumberOfEntries", kU8, kConst, kCn, 1, "entries"},
  {kStoreParam, 1, 1, "NMT_StoreParam_REC.AllParam_U32", kU32, kRw, kCn, 1, "write \"save\": store the values in use (bit 0: saves on command)"},
  {kRestoreDefParam, 0, 0, "NMT_RestoreDefParam_REC.NumberOfEntries", kU8, kConst, kCn, 1, "entries"},
  {kRestoreDefParam, 1, 1, "NMT_RestoreDefParam_REC.AllParam_U32", kU32, kRw, kCn, 1, "write \"load\": defaults from the next reset on (bit 0: restores on command)"},
  {kIdentity, 0, 0, "NMT_IdentityObject_REC.NumberOfEntries", kU8, kConst, kCn, 4, "entries"},
  {kIdentity, 1, 1, "NMT_IdentityObject_REC.VendorId_U32", kU32, kRo, kCn, 0, "vendor id"},
  {kIdentity, 2, 2, "NMT_IdentityObject_REC.ProductCode_U32", kU32, kRo, kCn, 0, "product code"},
  {kIdentity, 3, 3, "NMT_IdentityObject_REC.RevisionNo_U32", kU32, kRo, kCn, 0, "revision number"},
  {kIdentity, 4, 4, "NMT_IdentityObject_REC.SerialNo_U32", kU32, kRo, kCn, 0, "serial number"},
  {kVerifyConfiguration, 0, 0, "CFM_VerifyConfiguration_REC.NumberOfEntries", kU8, kConst, kCn, 2, "entries"},
  {kVerifyConfiguration, 1, 1, "CFM_VerifyConfiguration_REC.ConfDate_U32", kU32, kRw, kCn, 0, "configuration date (IdentResponse VerifyConfigurationDate)"},
  {kVerifyConfiguration, 2, 2, "CFM_VerifyConfiguration_REC.ConfTime_U32", kU32, kRw, kCn, 0, "configuration time (IdentResponse VerifyConfigurationTime)"},
  {kRxPdoComm, 0, 0, "PDO_RxCommParam_00h_REC.NumberOfEntries", kU8, kConst, kCn, 2, "entries"},
  {kRxPdoComm, 1, 1, "PDO_RxCommParam_00h_REC.NodeID_U8", kU8, kRw, kCn, 0, "node whose frame the RPDO is (0: the PReq)"},
  {kRxPdoComm, 2, 2, "PDO_RxCommParam_00h_REC.MappingVersion_U8", kU8, kRw, kCn, 0, "mapping version"},
  {kRxPdoMapping, 0, 0, "PDO_RxMappParam_00h_AU64.NumberOfEntries", kU8, kRw, kCn, 0, "mapped objects (0: mapping disabled, written first)"},
  {kRxPdoMapping, 1, 254, "PDO_RxMappParam_00h_AU64.ObjectMapping", kU64, kRw, kCn, 0, "PReq payload entry: length|offset bits, subindex, index"},
  {kRxPdoCommPresMn, 0, 0, "PDO_RxCommParam_01h_REC.NumberOfEntries", kU8, kConst, kCn, 2, "entries"},
  {kRxPdoCommPresMn, 1, 1, "PDO_RxCommParam_01h_REC.NodeID_U8", kU8, kRw, kCn, 0, "node whose frame the RPDO is (240: the PResMN)"},
  {kRxPdoCommPresMn, 2, 2, "PDO_RxCommParam_01h_REC.MappingVersion_U8", kU8, kRw, kCn, 0, "mapping version"},
  {kRxPdoMappingPresMn, 0, 0, "PDO_RxMappParam_01h_AU64.NumberOfEntries", kU8, kRw, kCn, 0, "mapped objects (0: mapping disabled, written first)"},
  {kRxPdoMappingPresMn, 1, 254, "PDO_RxMappParam_01h_AU64.ObjectMapping", kU64, kRw, kCn, 0, "entry of the frame NodeID_U8 names: length|offset bits, subindex, index"},
  {kTxPdoComm, 0, 0, "PDO_TxCommParam_00h_REC.NumberOfEntries", kU8, kConst, kCn, 2, "entries"},
  {kTxPdoComm, 1, 1, "PDO_TxCommParam_00h_REC.NodeID_U8", kU8, kRw, kCn, 0, "node the TPDO is for (0: the PRes)"},
  {kTxPdoComm, 2, 2, "PDO_TxCommParam_00h_REC.MappingVersion_U8", kU8, kRw, kCn, 0, "mapping version"},
  {kTxPdoMapping, 0, 0, "PDO_TxMappParam_00h_AU64.NumberOfEntries", kU8, kRw, kCn, 0, "mapped objects (0: mapping disabled, written first)"},
  {kTxPdoMapping, 1, 254, "PDO_TxMappParam_00h_AU64.ObjectMapping", kU64, kRw, kCn, 0, "PRes payload entry: length|offset bits, subindex, index"},
  {kMnCycTimeExceed, 3, 3, "DLL_MNCycTimeExceed_REC.Threshold_U32", kU32, kRw, kMn, 15, "cycle time exceeded threshold"},
  {kMnCnLossPResThreshold, 1, 254, "DLL_MNCNLossPResThreshold_AU32", kU32, kRw, kMn, 0, "loss of PRes threshold per CN (0: disabled)"},
  {kCnLossSoc, 0, 0, "DLL_CNLossSoC_REC.NumberOfEntries", kU8, kConst, kCn, 3, "entries"},
  {kCnLossSoc, 1, 1, "DLL_CNLossSoC_REC.CumulativeCnt_U32", kU32, kRw, kCn, 0, "SoC lost, cumulative"},
  {kCnLossSoc, 2, 2, "DLL_CNLossSoC_REC.ThresholdCnt_U32", kU32, kRo, kCn, 0, "threshold counter"},
  {kCnLossSoc, 3, 3, "DLL_CNLossSoC_REC.Threshold_U32", kU32, kRw, kCn, 15, "threshold"},
  {kCnLossSoa, 0, 0, "DLL_CNLossSoA_REC.NumberOfEntries", kU8, kConst, kCn, 3, "entries"},
  {kCnLossSoa, 1, 1, "DLL_CNLossSoA_REC.CumulativeCnt_U32", kU32, kRw, kCn, 0, "SoA lost, cumulative"},
  {kCnLossSoa, 2, 2, "DLL_CNLossSoA_REC.ThresholdCnt_U32", kU32, kRo, kCn, 0, "threshold counter"},
  {kCnLossSoa, 3, 3, "DLL_CNLossSoA_REC.Threshold_U32", kU32, kRw, kCn, 15, "threshold"},
  {kCnLossPReq, 0, 0, "DLL_CNLossPReq_REC.NumberOfEntries", kU8, kConst, kCn, 3, "entries"},
  {kCnLossPReq, 1, 1, "DLL_CNLossPReq_REC.CumulativeCnt_U32", kU32, kRw, kCn, 0, "PReq lost, cumulative"},
  {kCnLossPReq, 2, 2, "DLL_CNLossPReq_REC.ThresholdCnt_U32", kU32, kRo, kCn, 0, "threshold counter"},
  {kCnLossPReq, 3, 3, "DLL_CNLossPReq_REC.Threshold_U32", kU32, kRw, kCn, 15, "threshold"},
  {kCnCrcError, 0, 0, "DLL_CNCRCError_REC.NumberOfEntries", kU8, kConst, kCn, 3, "entries"},
  {kCnCrcError, 1, 1, "DLL_CNCRCError_REC.CumulativeCnt_U32", kU32, kRw, kCn, 0, "CRC errors, cumulative"},
  {kCnCrcError, 2, 2, "DLL_CNCRCError_REC.ThresholdCnt_U32", kU32, kRo, kCn, 0, "threshold counter"},
  {kCnCrcError, 3, 3, "DLL_CNCRCError_REC.Threshold_U32", kU32, kRw, kCn, 15, "threshold"},
  {kLossOfSocTolerance, 0, 0, "DLL_CNLossOfSocTolerance_U32", kU32, kRw, kCn, 300'000, "SoC jitter tolerated, ns"},
  {kConciseDcfList, 0, 0, "CFM_ConciseDcfList_ADOM.NumberOfEntries", kU8, kConst, kCn, 254, "entries"},
  {kConciseDcfList, 1, 254, "CFM_ConciseDcfList_ADOM", kDomain, kRw, kCn, 0, "concise DCF per node (the objects the MN writes to it)"},
  {kExpConfDateList, 1, 254, "CFM_ExpConfDateList_AU32", kU32, kRw, kMn, 0, "configuration date expected per node"},
  {kExpConfTimeList, 1, 254, "CFM_ExpConfTimeList_AU32", kU32, kRw, kMn, 0, "configuration time expected per node"},
  {kNodeAssignment, 1, 254, "NMT_NodeAssignment_AU32", kU32, kRw, kMn, 0, "node assignment per node (bit 3: mandatory, 8: async-only, 9: multiplexed, 14: PollResponse Chaining)"},
  {kMnDeviceTypeIdList, 1, 254, "NMT_MNDeviceTypeIdList_AU32", kU32, kRw, kMn, 0, "device type expected per node"},
  {kMnVendorIdList, 1, 254, "NMT_MNVendorIdList_AU32", kU32, kRw, kMn, 0, "vendor id expected per node"},
  {kMnProductCodeList, 1, 254, "NMT_MNProductCodeList_AU32", kU32, kRw, kMn, 0, "product code expected per node"},
  {kMnRevisionNoList, 1, 254, "NMT_MNRevisionNoList_AU32", kU32, kRw, kMn, 0, "revision number expected per node"},
  {kMnSerialNoList, 1, 254, "NMT_MNSerialNoList_AU32", kU32, kRw, kMn, 0, "serial number expected per node"},
  {kMnBootTime, 1, 1, "NMT_BootTime_REC.MNWaitNotAct_U32", kU32, kRw, kMn, 1'000'000, "MN listens in NOT_ACTIVE for another MN before it starts, µs"},
  {kMnBootTime, 2, 2, "NMT_BootTime_REC.MNTimeoutPreOp1_U32", kU32, kRw, kMn, 500'000, "MN in PRE_OPERATIONAL_1 until the mandatory CNs are identified, µs"},
  {kMnCycleTiming, 1, 1, "NMT_MNCycleTiming_REC.WaitSoCPReq_U32", kU32, kRw, kMn, 0, "pause SoC to first PReq, ns"},
  {kMnCycleTiming, 2, 2, "NMT_MNCycleTiming_REC.AsyncSlotTimeout_U32", kU32, kRw, kMn, 0, "wait for the invited ASnd, ns"},
  {kMnPReqPayloadLimitList, 1, 254, "NMT_MNPReqPayloadLimitList_AU16", kU16, kRw, kMn, 0, "PReq payload per node, bytes"},
  {kPResPayloadLimitList, 1, 254, "NMT_PResPayloadLimitList_AU16", kU16, kRw, kMn, 0, "PRes payload per node, bytes"},
  {kMnCnPResTimeout, 1, 254, "NMT_MNCNPResTimeout_AU32", kU32, kRw, kMn, 0, "PRes timeout per node, ns"},
  {kMultiplCycleAssign, 1, 254, "NMT_MultiplCycleAssign_AU8", kU8, kRw, kMn, 0, "multiplexed cycle slot per node (0: continuous)"},
  {kCycleTiming, 0, 0, "NMT_CycleTiming_REC.NumberOfEntries", kU8, kConst, kCn, 9, "entries"},
  {kCycleTiming, 1, 1, "NMT_CycleTiming_REC.IsochrTxMaxPayload_U16", kU16, kConst, kCn, 1490, "largest PRes payload the device sends"},
  {kCycleTiming, 2, 2, "NMT_CycleTiming_REC.IsochrRxMaxPayload_U16", kU16, kConst, kCn, 1490, "largest PReq payload the device takes"},
  {kCycleTiming, 3, 3, "NMT_CycleTiming_REC.PResMaxLatency_U32", kU32, kConst, kCn, 2000, "PReq to PRes, ns"},
  {kCycleTiming, 4, 4, "NMT_CycleTiming_REC.PReqActPayloadLimit_U16", kU16, kRw, kCn, 0, "PReq payload in use (≤ sub 2; 0: not written)"},
  {kCycleTiming, 5, 5, "NMT_CycleTiming_REC.PResActPayloadLimit_U16", kU16, kRw, kCn, 0, "PRes payload in use (≤ sub 1; 0: not written)"},
  {kCycleTiming, 6, 6, "NMT_CycleTiming_REC.ASndMaxLatency_U32", kU32, kConst, kCn, 2000, "SoA to ASnd, ns"},
  {kCycleTiming, 7, 7, "NMT_CycleTiming_REC.MultiplCycleCnt_U8", kU8, kRw, kCn, 0, "multiplexed cycle count"},
  {kCycleTiming, 8, 8, "NMT_CycleTiming_REC.AsyncMTU_U16", kU16, kRw, kCn, 300, "asynchronous MTU, bytes"},
  {kCycleTiming, 9, 9, "NMT_CycleTiming_REC.Prescaler_U16", kU16, kRw, kCn, 2, "SoC PS flag prescaler"},
});
// clang-format on
}  // namespace detail
using detail::kStandardObjects;

// The row of index/sub-index, or nullptr.
[[nodiscard]] constexpr const StandardObject* find_standard_object(uint16_t index,
                                                                   uint8_t subindex) noexcept {
  for (const StandardObject& o : kStandardObjects)
    if (o.index == index && subindex >= o.sub_first && subindex <= o.sub_last) return &o;
  return nullptr;
}
// True when the table has a row for `index` (any sub-index) held by `holder`.
[[nodiscard]] constexpr bool has_standard_index(uint16_t index, ObjHolder holder) noexcept {
  for (const StandardObject& o : kStandardObjects)
    if (o.index == index && o.holder == holder) return true;
  return false;
}

}  // namespace ds1928::powerlink
