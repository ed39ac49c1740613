// One frame of each POWERLINK type built by the codec, shared by the codec and Wireshark tests.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "powerlink/frames.hpp"

namespace ds1928::powerlink::test {

inline constexpr MacAddress kMnMac{0x02, 0x00, 0x00, 0x00, 0x00, 0xF0};
inline constexpr MacAddress kCnMac{0x02, 0x00, 0x00, 0x00, 0x00, 0x01};

struct Sample {
  std::string name;
  std::vector<uint8_t> bytes;
};

inline std::vector<Sample> build_samples() {
  std::vector<Sample> out;
  std::array<uint8_t, kMaxFrameSize> buf{};
  auto add = [&](const char* name, Result<std::size_t> len) {
    if (len) out.push_back({name, std::vector<uint8_t>(buf.begin(), buf.begin() + *len)});
  };
  Soc soc;
  soc.net_time = {1700000000, 123456789};
  soc.relative_time_us = 4242;
  add("SoC", build_soc(buf, soc_header(kMnMac), soc));
  std::array<uint8_t, 36> preq_payload{};
  for (std::size_t i = 0; i < preq_payload.size(); ++i) preq_payload[i] = static_cast<uint8_t>(i);
  PReq preq;
  preq.ready = true;
  preq.payload = preq_payload;
  add("PReq", build_preq(buf, preq_header(kMnMac, kCnMac, 1), preq));
  std::array<uint8_t, 46> pres_payload{};
  for (std::size_t i = 0; i < pres_payload.size(); ++i)
    pres_payload[i] = static_cast<uint8_t>(0xA0 + i);
  PRes pres;
  pres.nmt_state = NmtState::kOperational;
  pres.ready = true;
  pres.priority = 3;
  pres.request_count = 1;
  pres.payload = pres_payload;
  add("PRes", build_pres(buf, pres_header(kCnMac, 1), pres));
  SoA soa;
  soa.mn_nmt_state = NmtState::kOperational;
  soa.service = RequestedService::kStatusRequest;
  soa.target = 1;
  add("SoA StatusRequest", build_soa(buf, soa_header(kMnMac), soa));
  soa.service = RequestedService::kIdentRequest;
  add("SoA IdentRequest", build_soa(buf, soa_header(kMnMac), soa));
  soa.service = RequestedService::kUnspecifiedInvite;
  soa.target = kNodeMn;
  add("SoA UnspecifiedInvite", build_soa(buf, soa_header(kMnMac), soa));
  IdentResponse ident;
  ident.nmt_state = NmtState::kPreOperational1;
  ident.mtu = 300;
  ident.poll_in_size = 46;
  ident.poll_out_size = 36;
  ident.response_time_ns = 25000;
  ident.device_type = 0x000F0191;
  ident.vendor_id = 0x0000001A;
  ident.product_code = 0x00001234;
  ident.ip_address = 0x0164A8C0;
  ident.subnet_mask = 0x00FFFFFF;
  ident.default_gateway = 0xFE64A8C0;
  const char host[] = "ds1928-sim";
  std::copy(std::begin(host), std::end(host) - 1, ident.host_name.begin());
  add("IdentResponse", build_ident_response(buf, asnd_header(kCnMac, 1, kNodeMn), ident));
  StatusResponse status;
  status.nmt_state = NmtState::kPreOperational2;
  status.exception_new = true;
  std::array<ErrorEntry, 2> entries{};
  entries[0] = {0x1000, 0x8235, 0x1122334455667788ULL, {1, 2, 3, 4, 5, 6, 7, 8}};
  entries[1] = {0x1000, 0x8700, 42, {}};
  add("StatusResponse",
      build_status_response(buf, asnd_header(kCnMac, 1, kNodeMn), status, entries));
  add("NMTCommand", build_nmt_command(buf, asnd_header(kMnMac, kNodeMn, 1),
                                      {static_cast<uint8_t>(NmtCommandId::kStartNode), {}}));
  add("NMTRequest", build_nmt_request(buf, asnd_header(kCnMac, 1, kNodeMn),
                                      {static_cast<uint8_t>(NmtCommandId::kResetNode), 1, {}}));
  Sdo open;
  open.sequence = {0, SdoRecvCon::kNone, 0, SdoSendCon::kInit};
  add("SDO sequence init", build_sdo(buf, asnd_header(kMnMac, kNodeMn, 1), open));
  std::array<uint8_t, 5> write_payload{0x01, 0x20, 0x01, 0x00, 0x01};  // 0x2001/1 := 1
  Sdo write;
  write.sequence = {1, SdoRecvCon::kValid, 2, SdoSendCon::kValid};
  write.has_command = true;
  write.command.transaction_id = 7;
  write.command.command_id = static_cast<uint8_t>(SdoCommandId::kWriteByIndex);
  write.command.payload = write_payload;
  add("SDO WriteByIndex", build_sdo(buf, asnd_header(kMnMac, kNodeMn, 1), write));
  std::array<uint8_t, 4> read_payload{0x01, 0x20, 0x07, 0x00};
  Sdo read = write;
  read.command.command_id = static_cast<uint8_t>(SdoCommandId::kReadByIndex);
  read.command.payload = read_payload;
  read.sequence = {1, SdoRecvCon::kValid, 3, SdoSendCon::kValid};
  add("SDO ReadByIndex", build_sdo(buf, asnd_header(kMnMac, kNodeMn, 1), read));
  std::array<uint8_t, 2> read_data{0x20, 0x03};
  Sdo read_rsp = read;
  read_rsp.command.response = true;
  read_rsp.command.payload = read_data;
  read_rsp.sequence = {3, SdoRecvCon::kValid, 2, SdoSendCon::kValid};
  add("SDO ReadByIndex response", build_sdo(buf, asnd_header(kCnMac, 1, kNodeMn), read_rsp));
  std::array<uint8_t, 4> abort_code{0x00, 0x00, 0x02, 0x06};
  Sdo abort = read_rsp;
  abort.command.abort = true;
  abort.command.payload = abort_code;
  abort.sequence = {3, SdoRecvCon::kValid, 3, SdoSendCon::kValid};
  add("SDO abort", build_sdo(buf, asnd_header(kCnMac, 1, kNodeMn), abort));
  return out;
}

}  // namespace ds1928::powerlink::test
