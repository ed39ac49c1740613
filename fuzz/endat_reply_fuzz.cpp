// EnDat command codec on received Flatstream messages: the master's strict reply decoder (for
// any request it could have sent) and the module's request decoder, with round trips for what
// they accept.
#include <cstdlib>

#include "endat/command.hpp"
#include "fuzz_input.hpp"

using namespace ds1928::endat;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  ds1928::fuzz::Input in(data, size);
  Request request;
  request.command = kAllCommands[in.u8() % kAllCommands.size()];
  request.mrs = in.u8();
  request.block = in.u8();
  request.parameter = in.u8();
  request.value = in.u16();
  const auto message = in.rest();
  if (auto reply = decode_reply(request, message)) {
    if (reply->word_count > reply->words.size()) std::abort();
    (void)reply->value();
  }
  if (auto req = decode_request(message)) {
    // A request the module accepts and the master would send encodes to the same request,
    // and the module's success reply to it decodes on the master.
    if (!validate(*req, CommandSet::EnDat22)) {
      auto encoded = encode_request(*req, CommandSet::EnDat22);
      if (!encoded) std::abort();
      auto again = decode_request(encoded->span());
      if (!again || !again->same_as(*req)) std::abort();
      const std::array<uint16_t, 4> words{1, 2, 3, 4};
      if (!decode_reply(*req, encode_reply(*req, words).span())) std::abort();
    }
  }
  return 0;
}
