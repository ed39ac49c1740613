// Writes the seed corpora (fuzz/corpus/<target>/) from the codecs' own builders and the test
// suite's sample frames, so the seeds are valid inputs of each harness's format. The text seeds
// (configuration files, request lines) are plain files kept in the corpus directly.
//   fuzz_make_seeds fuzz/corpus
#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "../tests/powerlink/frame_samples.hpp"
#include "can/can_error_frame.hpp"
#include "canio/object_codec.hpp"
#include "canio/sdo_expedited.hpp"
#include "endat/command.hpp"
#include "flatstream/receiver.hpp"
#include "flatstream/sender.hpp"
#include "powerlink/frames.hpp"

namespace fs = std::filesystem;
namespace pl = ds1928::powerlink;
namespace fst = ds1928::flatstream;
namespace endat = ds1928::endat;
namespace can = ds1928::canio;

namespace {

fs::path root;

void write(const std::string& target, const std::string& name, const std::vector<uint8_t>& b) {
  const fs::path dir = root / target;
  fs::create_directories(dir);
  std::string file;
  for (char c : name) file += (std::isalnum(static_cast<unsigned char>(c)) ? c : '_');
  std::ofstream(dir / file, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

void powerlink_seeds() {
  for (const auto& s : pl::test::build_samples()) {
    write("powerlink_frame", s.name, s.bytes);
    // SDO harness: the ASnd SDO layers (from offset 18) as a chunk to the node they address,
    // after a chunk that starts a client transfer.
    if (s.name.rfind("SDO", 0) == 0) {
      const bool to_server = s.bytes[15] == 1;  // destination node
      std::vector<uint8_t> chunk;
      chunk.push_back(0x04);  // client.read(0x2001, 7)
      chunk.insert(chunk.end(), {0x01, 0x20, 0x07});
      const std::size_t n = s.bytes.size() - pl::kSdoSeqOffset;
      chunk.push_back(to_server ? 0x11 : 0x10);
      chunk.push_back(static_cast<uint8_t>(n & 0xFF));
      chunk.push_back(static_cast<uint8_t>(n >> 8));
      chunk.insert(chunk.end(), s.bytes.begin() + pl::kSdoSeqOffset, s.bytes.end());
      write("sdo", s.name, chunk);
    }
  }
}

// A whole conversation: the sender's cycles as the receiver harness reads them.
void flatstream_seeds() {
  for (uint8_t mtu : {uint8_t{3}, uint8_t{7}, uint8_t{27}}) {
    for (auto layout : {fst::Layout::Default, fst::Layout::MultiSegmentMtu,
                        fst::Layout::LargeSegments, fst::Layout::LargeMultiSegment}) {
      fst::SequenceSender tx({.mtu = mtu, .layout = layout, .forward = 1});
      fst::SequenceReceiver rx({.mtu = mtu});
      std::vector<uint8_t> seed{static_cast<uint8_t>(mtu - 2), 0};
      for (uint8_t len : {uint8_t{1}, uint8_t{5}, uint8_t{40}, uint8_t{2}}) {
        std::vector<uint8_t> msg(len);
        for (std::size_t i = 0; i < len; ++i) msg[i] = static_cast<uint8_t>(0x30 + i);
        (void)tx.submit(msg, len);
      }
      uint64_t now = 0;
      for (int cycle = 0; cycle < 60; ++cycle) {
        tx.step(rx.ack(), rx.sync_ack(), ++now);
        rx.step(tx.counter(), tx.sync_bit(), tx.mtu(), now);
        seed.push_back(static_cast<uint8_t>(tx.counter() | (tx.sync_bit() ? 0x08 : 0) | 0x10));
        seed.insert(seed.end(), tx.mtu().begin(), tx.mtu().begin() + mtu);
        fst::Message m;
        while (rx.take(m)) {
        }
      }
      write("flatstream_receiver", "mtu" + std::to_string(mtu) + "_" + fst::to_string(layout),
            seed);
    }
  }
}

void endat_seeds() {
  const std::array<uint16_t, 4> words{0x1234, 0x0002, 0x0003, 0x0004};
  const std::array requests{endat::Request::reset(),
                            endat::Request::acknowledge(),
                            endat::Request::read(0xA1, 0x0D),
                            endat::Request::write(0xA1, 0x0D, 0xBEEF),
                            endat::Request::read_block(0xA1, 2, 5),
                            endat::Request::write_block(0xA1, 2, 5, 7),
                            endat::Request::read_info(1, 0x40),
                            endat::Request::read_info(4, 0x40)};
  for (const auto& r : requests) {
    const std::vector<uint8_t> head{
        static_cast<uint8_t>(
            std::find(endat::kAllCommands.begin(), endat::kAllCommands.end(), r.command) -
            endat::kAllCommands.begin()),
        r.mrs,
        r.block,
        r.parameter,
        static_cast<uint8_t>(r.value & 0xFF),
        static_cast<uint8_t>(r.value >> 8)};
    const std::string name(endat::command_name(r.command));
    auto reply = head;
    const auto ok = endat::encode_reply(r, words);
    reply.insert(reply.end(), ok.span().begin(), ok.span().end());
    write("endat_reply", name + "_reply", reply);
    auto failure = head;
    const auto f = endat::encode_failure_reply(static_cast<uint8_t>(r.command),
                                               endat::FailureReason::CrcError);
    failure.insert(failure.end(), f.span().begin(), f.span().end());
    write("endat_reply", name + "_failure", failure);
    if (auto req = endat::encode_request(r, endat::CommandSet::EnDat22)) {
      auto request = head;
      request.insert(request.end(), req->span().begin(), req->span().end());
      write("endat_reply", name + "_request", request);
    }
  }
}

// One CAN frame in the canio_frame harness' layout (flags, identifier, dlc, data), then the
// node the SDO parser is asked about and an SDO request to match the frame against.
std::vector<uint8_t> canio_input(const can::CanFrame& f, uint8_t node,
                                 std::initializer_list<uint8_t> request) {
  std::vector<uint8_t> b{
      static_cast<uint8_t>((f.extended ? 1 : 0) | (f.rtr ? 2 : 0) | (f.error ? 4 : 0)),
      static_cast<uint8_t>(f.id),
      static_cast<uint8_t>(f.id >> 8),
      static_cast<uint8_t>(f.id >> 16),
      static_cast<uint8_t>(f.id >> 24),
      f.dlc};
  b.insert(b.end(), f.data.begin(), f.data.end());
  b.push_back(static_cast<uint8_t>(node - 1));
  b.insert(b.end(), request);
  return b;
}

void canio_seeds() {
  ds1928::ModuleInputs in;
  in.position_hw = 0x00000012;
  in.position_lw = 0x3456789A;
  in.pos_cycle = -3;
  in.error_info = 0x10;
  in.input_sequence = 0x85;
  in.rx_bytes = {0xC3, 0x02, 0x40, 0x00, 0x00};
  can::CanObject o{};
  can::pack_position_object(in, can::ByteOrder::Little, o);
  write("canio_frame", "position_object", canio_input(can::make_standard_frame(0x181, o), 1, {}));
  can::pack_status_object(in, o);
  write("canio_frame", "status_object", canio_input(can::make_standard_frame(0x281, o), 1, {}));
  ds1928::ModuleOutputs out;
  out.output_sequence = 0x81;
  out.tx_bytes = {0xC2, 0x03, 0x00, 0x00, 0x00};
  out.ack_error_info = 0x10;
  can::pack_output_object(out, o);
  write("canio_frame", "output_object", canio_input(can::make_standard_frame(0x201, o), 1, {}));

  // SDO: a write of EnDatMode and its acknowledgement, a read and its answer, an abort.
  const can::SdoMessage write_req{can::SdoCommand::DownloadRequest, 0x2101, 1, 1, 0x01};
  const can::SdoMessage write_ack{can::SdoCommand::DownloadResponse, 0x2101, 1, 0, 0};
  const can::SdoMessage read_req{can::SdoCommand::UploadRequest, 0x2102, 2, 0, 0};
  const can::SdoMessage read_ans{can::SdoCommand::UploadResponse, 0x2102, 2, 2, 0x0005};
  const can::SdoMessage abort{can::SdoCommand::Abort, 0x2102, 2, 0, 0x06020000};
  if (auto f = can::build_sdo_request(5, write_req))
    write("canio_frame", "sdo_download_request", canio_input(*f, 5, {1, 0x01, 0x21, 1, 0, 1, 0}));
  if (auto f = can::build_sdo_response(5, write_ack))
    write("canio_frame", "sdo_download_response", canio_input(*f, 5, {1, 0x01, 0x21, 1, 0, 1, 0}));
  if (auto f = can::build_sdo_request(5, read_req))
    write("canio_frame", "sdo_upload_request", canio_input(*f, 5, {0, 0x02, 0x21, 2, 0, 0, 2}));
  if (auto f = can::build_sdo_response(5, read_ans))
    write("canio_frame", "sdo_upload_response", canio_input(*f, 5, {0, 0x02, 0x21, 2, 0, 0, 2}));
  if (auto f = can::build_sdo_response(5, abort))
    write("canio_frame", "sdo_abort", canio_input(*f, 5, {0, 0x02, 0x21, 2, 0, 0, 2}));

  // Error frames as the kernel reports them: bus-off, error-passive, a stuff error, restarted.
  can::CanErrorEvent bus_off;
  bus_off.bus_off = true;
  write("canio_frame", "error_bus_off", canio_input(can::encode_error_frame(bus_off), 1, {}));
  can::CanErrorEvent passive;
  passive.controller = true;
  passive.controller_status = can::err_ctrl::kRxPassive | can::err_ctrl::kTxPassive;
  passive.counters_flagged = true;
  passive.tx_error_count = 130;
  passive.rx_error_count = 128;
  write("canio_frame", "error_passive", canio_input(can::encode_error_frame(passive), 1, {}));
  can::CanErrorEvent stuff;
  stuff.protocol = true;
  stuff.protocol_type = can::err_prot::kStuff | can::err_prot::kTx;
  stuff.protocol_location = 0x0A;
  write("canio_frame", "error_stuff", canio_input(can::encode_error_frame(stuff), 1, {}));
  can::CanErrorEvent restarted;
  restarted.restarted = true;
  write("canio_frame", "error_restarted", canio_input(can::encode_error_frame(restarted), 1, {}));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR\n", argv[0]);
    return 2;
  }
  root = argv[1];
  powerlink_seeds();
  flatstream_seeds();
  endat_seeds();
  canio_seeds();
  return 0;
}
