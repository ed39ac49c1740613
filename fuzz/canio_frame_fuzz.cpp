// CAN-I/O frames as they arrive from the bus: the cyclic object decoders (both byte orders), the
// SocketCAN error-frame decoder and the expedited SDO parser and response matcher, with round
// trips for what they accept.
#include <cstdlib>
#include <cstring>

#include "can/can_error_frame.hpp"
#include "canio/object_codec.hpp"
#include "canio/sdo_expedited.hpp"
#include "fuzz_input.hpp"

using namespace ds1928;
using namespace ds1928::canio;

namespace {

CanFrame take_frame(fuzz::Input& in) {
  CanFrame f;
  const uint8_t flags = in.u8();
  f.extended = (flags & 1) != 0;
  f.rtr = (flags & 2) != 0;
  f.error = (flags & 4) != 0;
  f.id = static_cast<uint32_t>(in.u16()) | (static_cast<uint32_t>(in.u16()) << 16);
  f.dlc = in.u8() & 0x0F;  // 9..15 too: a corrupt length must not be read past the payload
  const auto data = in.bytes(8);
  std::memcpy(f.data.data(), data.data(), data.size());
  return f;
}

void objects(const CanFrame& f) {
  const auto bytes = f.payload();
  for (const ByteOrder order : {ByteOrder::Little, ByteOrder::Big}) {
    ModuleInputs in;
    if (unpack_position_object(bytes, order, in)) {
      CanObject again{};
      pack_position_object(in, order, again);
      if (bytes.size() != kObjectBytes || std::memcmp(again.data(), bytes.data(), 8) != 0)
        std::abort();
    }
  }
  ModuleInputs in;
  if (unpack_status_object(bytes, in)) {
    CanObject again{};
    pack_status_object(in, again);
    if (bytes.size() != kObjectBytes || std::memcmp(again.data(), bytes.data(), 8) != 0)
      std::abort();
  }
  ModuleOutputs out;
  if (unpack_output_object(bytes, out)) {
    CanObject again{};
    pack_output_object(out, again);
    if (bytes.size() < 7 || std::memcmp(again.data(), bytes.data(), 7) != 0) std::abort();
  }
}

void error_frame(const CanFrame& f) {
  char text[96];
  auto event = decode_error_frame(f);
  if (!event) return;
  (void)describe(*event, text, sizeof(text));  // truncates: the text must stay terminated
  if (std::memchr(text, '\0', sizeof(text)) == nullptr) std::abort();
  (void)event->state_change();
  // What the decoder accepted, encoded the way a driver would, decodes to the same event.
  auto again = decode_error_frame(encode_error_frame(*event));
  if (!again || !(*again == *event)) std::abort();
}

void sdo(const CanFrame& f, fuzz::Input& in) {
  const uint8_t node = static_cast<uint8_t>(1 + in.u8() % 127);
  for (const bool from_server : {false, true}) {
    auto m = parse_sdo(node, from_server, f);
    if (!m) continue;
    auto rebuilt = from_server ? build_sdo_response(node, *m) : build_sdo_request(node, *m);
    if (!rebuilt) std::abort();
    auto again = parse_sdo(node, from_server, *rebuilt);
    if (!again || !(*again == *m)) std::abort();
  }
  SdoMessage request;
  request.command = (in.u8() & 1) ? SdoCommand::DownloadRequest : SdoCommand::UploadRequest;
  request.index = in.u16();
  request.subindex = in.u8();
  request.size = request.command == SdoCommand::DownloadRequest ? 1 + in.u8() % 4 : 0;
  request.value = in.u16();
  const uint8_t expected_size = in.u8() % 5;
  if (auto r = match_sdo_response(node, request, f, expected_size)) {
    if (r->index != request.index || r->subindex != request.subindex) std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  fuzz::Input in(data, size);
  const CanFrame f = take_frame(in);
  objects(f);
  error_frame(f);
  sdo(f, in);
  return 0;
}
