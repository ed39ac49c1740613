// Flatstream receiver: a peer that sends any counter, SyncBit and MTU bytes, cycle after cycle.
// Input: [mtu, forward delay] then per cycle [control, MTU bytes...]; control bits 0-2 are the
// counter, bit 3 the SyncBit, bit 4 "take the queued messages", bits 5-6 the time step, all of
// 4-7 set resets the direction.
#include <cstdlib>

#include "flatstream/receiver.hpp"
#include "fuzz_input.hpp"

using namespace ds1928::flatstream;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  ds1928::fuzz::Input in(data, size);
  ReceiverConfig config;
  config.mtu = static_cast<uint8_t>(2 + in.u8() % (kMaxMtu - 1));  // 2..27
  config.forward_delay_us = in.u8() & 0x0F;
  SequenceReceiver rx(config);
  uint64_t now_us = 0;
  Message m;
  while (!in.empty()) {
    const uint8_t ctl = in.u8();
    MtuBytes bytes{};
    const auto b = in.bytes(config.mtu);
    std::copy(b.begin(), b.end(), bytes.begin());
    now_us += 1 + ((ctl >> 5) & 3);
    rx.step(ctl & 0x07, (ctl & 0x08) != 0, bytes, now_us);
    if (rx.pending() > kQueueDepth) std::abort();
    if (ctl & 0x10) {
      while (rx.take(m))
        if (m.size > kMaxMessageSize) std::abort();
    }
    if ((ctl & 0xF0) == 0xF0) rx.reset();
    if (rx.ack() > 0x07) std::abort();
  }
  return 0;
}
