// Sequence layer: stop-and-wait. Every frame carrying command data advances the sender's
// sequence number; the peer answers it with a command frame or a sequence-only acknowledgement
// whose receive sequence number names it. Segmented transfers move one segment per answer, which
// is all POWERLINK allows anyway: each ASnd needs its own invitation in the SoA.
#include "powerlink/sdo.hpp"

#include <algorithm>
#include <cstring>

namespace ds1928::powerlink {
namespace {

constexpr std::size_t kIndexHeader = 4;  // index u16, subindex u8, reserved u8

[[nodiscard]] constexpr uint8_t next_seq(uint8_t s) noexcept {
  return (s + 1) & 0x3F;
}

}  // namespace

// ---- Client -------------------------------------------------------------------------------------

SdoClient::SdoClient(const SdoClientConfig& config, FrameSink send, Completion done)
    : config_(config), send_(std::move(send)), done_(std::move(done)) {
  config_.max_segment = std::clamp<std::size_t>(config_.max_segment, 8, kMaxSdoSegment - 4);
}

void SdoClient::send_frame(bool with_command, const SdoCommand& cmd) noexcept {
  Sdo sdo;
  if (with_command) send_seq_ = next_seq(send_seq_);
  sdo.sequence = {recv_seq_, SdoRecvCon::kValid, send_seq_, SdoSendCon::kValid};
  sdo.has_command = with_command;
  sdo.command = cmd;
  auto len = build_sdo(frame_, asnd_header(config_.own_mac, config_.own_node, config_.node), sdo);
  if (len) send_(std::span<const uint8_t>(frame_.data(), *len));
}

void SdoClient::send_ack() noexcept {
  send_frame(false, {});
}

std::error_code SdoClient::read(uint16_t index, uint8_t subindex, int64_t now_ns) noexcept {
  if (busy()) return SdoError::kBusy;
  is_write_ = false;
  index_ = index;
  subindex_ = subindex;
  size_ = 0;
  start_command(now_ns);
  return {};
}

std::error_code SdoClient::write(uint16_t index, uint8_t subindex, std::span<const uint8_t> data,
                                 int64_t now_ns) noexcept {
  if (busy()) return SdoError::kBusy;
  if (data.size() > kMaxSdoTransfer) return SdoError::kDataTooLarge;
  is_write_ = true;
  index_ = index;
  subindex_ = subindex;
  // The command payload stream: index header, then the data.
  store_le16(buffer_.data(), index);
  buffer_[2] = subindex;
  buffer_[3] = 0;
  std::copy(data.begin(), data.end(), buffer_.begin() + kIndexHeader);
  size_ = kIndexHeader + data.size();
  start_command(now_ns);
  return {};
}

void SdoClient::start_command(int64_t now_ns) noexcept {
  transaction_ = static_cast<uint8_t>(transaction_ + 1);
  segmenter_.start(size_);
  expected_ = 0;
  deadline_ns_ = now_ns + config_.timeout_ns;
  if (!connected_) {
    state_ = State::kOpening;
    send_seq_ = 0;
    recv_seq_ = 0;
    Sdo sdo;
    sdo.sequence = {0, SdoRecvCon::kNone, 0, SdoSendCon::kInit};
    auto len = build_sdo(frame_, asnd_header(config_.own_mac, config_.own_node, config_.node), sdo);
    if (len) send_(std::span<const uint8_t>(frame_.data(), *len));
    return;
  }
  send_command();
}

void SdoClient::send_command() noexcept {
  if (!is_write_) {
    std::array<uint8_t, kIndexHeader> req{};
    store_le16(req.data(), index_);
    req[2] = subindex_;
    SdoCommand cmd;
    cmd.transaction_id = transaction_;
    cmd.command_id = static_cast<uint8_t>(SdoCommandId::kReadByIndex);
    cmd.payload = req;
    state_ = State::kWaitResponse;
    send_frame(true, cmd);
    return;
  }
  state_ = State::kSending;
  send_next_write_segment();
}

// ---- Segmenter ----------------------------------------------------------------------------------

SdoSegmenter::Segment SdoSegmenter::next(std::size_t max_segment) noexcept {
  Segment seg;
  const std::size_t remaining = size_ - offset_;
  seg.offset = offset_;
  seg.length = std::min(remaining, max_segment);
  if (offset_ == 0 && seg.length == remaining) {
    seg.segmentation = SdoSegmentation::kExpedited;
  } else if (offset_ == 0) {
    seg.segmentation = SdoSegmentation::kInitiate;
    seg.total_size = static_cast<uint32_t>(size_);
  } else {
    seg.segmentation =
        seg.length == remaining ? SdoSegmentation::kComplete : SdoSegmentation::kSegment;
  }
  offset_ += seg.length;
  return seg;
}

void SdoClient::send_next_write_segment() noexcept {
  SdoCommand cmd;
  cmd.transaction_id = transaction_;
  cmd.command_id = static_cast<uint8_t>(SdoCommandId::kWriteByIndex);
  const SdoSegmenter::Segment seg = segmenter_.next(config_.max_segment);
  cmd.segmentation = seg.segmentation;
  cmd.total_size = seg.total_size;
  cmd.payload = std::span<const uint8_t>(buffer_.data() + seg.offset, seg.length);
  if (segmenter_.done()) state_ = State::kWaitResponse;
  send_frame(true, cmd);
}

void SdoClient::finish(std::error_code ec, std::span<const uint8_t> data) noexcept {
  state_ = State::kIdle;
  if (done_) done_(ec, data);
}

void SdoClient::abort(std::error_code reason, int64_t) noexcept {
  if (!busy()) return;
  if (connected_) {
    std::array<uint8_t, 4> code{};
    store_le32(code.data(), to_sdo_abort_code(reason));
    SdoCommand cmd;
    cmd.transaction_id = transaction_;
    cmd.abort = true;
    cmd.command_id =
        static_cast<uint8_t>(is_write_ ? SdoCommandId::kWriteByIndex : SdoCommandId::kReadByIndex);
    cmd.payload = code;
    send_frame(true, cmd);
  }
  finish(reason, {});
}

void SdoClient::reset() noexcept {
  connected_ = false;
  if (busy()) finish(SdoError::kConnectionLost, {});
}

void SdoClient::tick(int64_t now_ns) noexcept {
  if (busy() && now_ns >= deadline_ns_) {
    abort(SdoError::kTimeout, now_ns);
    // The server may have lost state; the next transfer reopens the connection.
    connected_ = false;
  }
}

void SdoClient::receive(const Sdo& sdo, int64_t now_ns) noexcept {
  const SdoSequence& seq = sdo.sequence;
  if (state_ == State::kOpening) {
    if (seq.recv_con == SdoRecvCon::kInit && seq.send_con == SdoSendCon::kInit) {
      Sdo ack;
      ack.sequence = {0, SdoRecvCon::kInit, 0, SdoSendCon::kValid};
      auto len =
          build_sdo(frame_, asnd_header(config_.own_mac, config_.own_node, config_.node), ack);
      if (len) send_(std::span<const uint8_t>(frame_.data(), *len));
      deadline_ns_ = now_ns + config_.timeout_ns;
    } else if (seq.recv_con == SdoRecvCon::kValid && seq.send_con == SdoSendCon::kValid) {
      connected_ = true;
      recv_seq_ = seq.send_seq;
      send_seq_ = seq.recv_seq;
      deadline_ns_ = now_ns + config_.timeout_ns;
      send_command();
    }
    return;
  }
  if (!busy() || !connected_) return;
  if (seq.recv_con == SdoRecvCon::kError || seq.send_con == SdoSendCon::kInit ||
      seq.recv_con == SdoRecvCon::kNone) {
    connected_ = false;
    finish(SdoError::kConnectionLost, {});
    return;
  }
  if (!sdo.has_command) {
    // Acknowledgement of our last segment.
    if (state_ == State::kSending && seq.recv_seq == send_seq_) {
      deadline_ns_ = now_ns + config_.timeout_ns;
      send_next_write_segment();
    }
    return;
  }
  if (seq.send_seq == recv_seq_) return;  // repeated frame
  if (seq.send_seq != next_seq(recv_seq_)) {
    abort(make_sdo_abort_error(sdo_abort::kInvalidSequence), now_ns);
    connected_ = false;
    return;
  }
  recv_seq_ = seq.send_seq;
  const SdoCommand& c = sdo.command;
  if (!c.response || c.transaction_id != transaction_) {
    abort(SdoError::kProtocol, now_ns);
    return;
  }
  deadline_ns_ = now_ns + config_.timeout_ns;
  if (c.abort) {
    // The abort code is 4 bytes; a shorter payload would read past it (into padding or beyond).
    if (c.payload.size() < 4) {
      finish(make_error_code(SdoError::kProtocol), {});
      return;
    }
    finish(make_sdo_abort_error(load_le32(c.payload.data())), {});
    return;
  }
  if (is_write_) {
    finish({}, {});
    return;
  }
  // Read response.
  switch (c.segmentation) {
    case SdoSegmentation::kExpedited:
      finish({}, c.payload);
      return;
    case SdoSegmentation::kInitiate:
      if (c.total_size > kMaxSdoTransfer) {
        abort(SdoError::kDataTooLarge, now_ns);
        return;
      }
      expected_ = c.total_size;
      size_ = 0;
      state_ = State::kReceiving;
      [[fallthrough]];
    case SdoSegmentation::kSegment:
    case SdoSegmentation::kComplete:
      if (state_ != State::kReceiving || size_ + c.payload.size() > expected_) {
        abort(SdoError::kProtocol, now_ns);
        return;
      }
      std::copy(c.payload.begin(), c.payload.end(), buffer_.begin() + size_);
      size_ += c.payload.size();
      if (c.segmentation == SdoSegmentation::kComplete) {
        if (size_ != expected_) {
          abort(SdoError::kProtocol, now_ns);
          return;
        }
        send_ack();
        finish({}, std::span<const uint8_t>(buffer_.data(), size_));
      } else {
        send_ack();
      }
      return;
  }
}

// ---- Server -------------------------------------------------------------------------------------

SdoServer::SdoServer(const SdoServerConfig& config, SdoObjectAccess& objects, FrameSink send)
    : config_(config), objects_(objects), send_(std::move(send)) {
  config_.max_segment = std::clamp<std::size_t>(config_.max_segment, 8, kMaxSdoSegment - 4);
}

void SdoServer::reset() noexcept {
  connected_ = false;
  in_write_ = in_read_ = false;
}

void SdoServer::tick(int64_t now_ns) noexcept {
  if ((in_write_ || in_read_) && now_ns >= deadline_ns_) in_write_ = in_read_ = false;
}

void SdoServer::send_frame(bool with_command, const SdoCommand& cmd) noexcept {
  Sdo sdo;
  if (with_command) send_seq_ = next_seq(send_seq_);
  sdo.sequence = {recv_seq_, SdoRecvCon::kValid, send_seq_, SdoSendCon::kValid};
  sdo.has_command = with_command;
  sdo.command = cmd;
  auto len =
      build_sdo(frame_, asnd_header(config_.own_mac, config_.own_node, config_.client_node), sdo);
  if (len) send_(std::span<const uint8_t>(frame_.data(), *len));
}

void SdoServer::send_abort(uint8_t transaction, uint8_t command_id, uint32_t code) noexcept {
  std::array<uint8_t, 4> bytes{};
  store_le32(bytes.data(), code);
  SdoCommand cmd;
  cmd.transaction_id = transaction;
  cmd.response = true;
  cmd.abort = true;
  cmd.command_id = command_id;
  cmd.payload = bytes;
  in_write_ = in_read_ = false;
  send_frame(true, cmd);
}

void SdoServer::receive(const Sdo& sdo, int64_t now_ns) noexcept {
  const SdoSequence& seq = sdo.sequence;
  auto reply_seq = [&](SdoRecvCon rcon, SdoSendCon scon) {
    Sdo r;
    r.sequence = {seq.send_seq, rcon, 0, scon};
    auto len =
        build_sdo(frame_, asnd_header(config_.own_mac, config_.own_node, config_.client_node), r);
    if (len) send_(std::span<const uint8_t>(frame_.data(), *len));
  };
  if (seq.send_con == SdoSendCon::kInit) {  // client opens (or reopens) the connection
    reset();
    reply_seq(SdoRecvCon::kInit, SdoSendCon::kInit);
    return;
  }
  if (seq.send_con == SdoSendCon::kNone) {
    // The client closes the connection: nothing to answer. A close answered with a close reaches
    // the client in a later async slot, after it may have opened its next connection, and ends
    // that one (openPOWERLINK's MN closes after each transfer and after resetting a node).
    reset();
    return;
  }
  if (!connected_) {
    if (seq.recv_con == SdoRecvCon::kInit && seq.send_con == SdoSendCon::kValid) {
      connected_ = true;
      recv_seq_ = seq.send_seq;
      send_seq_ = 0;
      reply_seq(SdoRecvCon::kValid, SdoSendCon::kValid);
    } else if (sdo.has_command) {
      // No connection: tell the client so it reopens.
      reply_seq(SdoRecvCon::kNone, SdoSendCon::kNone);
    }
    // A bare acknowledgement of a connection this side no longer has (it was reset) asks for
    // nothing; answered, it would reach the client after it opened its next connection.
    return;
  }
  if (!sdo.has_command) {
    if (in_read_ && seq.recv_seq == send_seq_) {
      deadline_ns_ = now_ns + config_.timeout_ns;
      send_read_segment();
    }
    return;
  }
  if (seq.send_seq == recv_seq_) return;  // repeated frame
  if (seq.send_seq != next_seq(recv_seq_)) {
    recv_seq_ = seq.send_seq;
    send_abort(sdo.command.transaction_id, sdo.command.command_id, sdo_abort::kInvalidSequence);
    return;
  }
  recv_seq_ = seq.send_seq;
  handle_command(sdo.command, now_ns);
}

void SdoServer::handle_command(const SdoCommand& c, int64_t now_ns) noexcept {
  if (c.abort) {  // the client gave up
    in_write_ = in_read_ = false;
    return;
  }
  if (c.response) return;
  SdoCommand rsp;
  rsp.transaction_id = c.transaction_id;
  rsp.response = true;
  rsp.command_id = c.command_id;
  deadline_ns_ = now_ns + config_.timeout_ns;

  if (c.command_id == static_cast<uint8_t>(SdoCommandId::kReadByIndex)) {
    if (c.segmentation != SdoSegmentation::kExpedited || c.payload.size() < kIndexHeader) {
      send_abort(c.transaction_id, c.command_id, sdo_abort::kTypeLength);
      return;
    }
    const uint16_t index = load_le16(c.payload.data());
    const uint8_t subindex = c.payload[2];
    std::size_t size = 0;
    const uint32_t code = objects_.read_object(
        index, subindex, std::span<uint8_t>(buffer_.data(), kMaxSdoTransfer), size);
    if (code != 0) {
      send_abort(c.transaction_id, c.command_id, code);
      return;
    }
    size = std::min(size, kMaxSdoTransfer);
    transaction_ = c.transaction_id;
    size_ = size;
    // Expedited when it fits one segment, else Initiate now and the rest on the client's acks.
    segmenter_.start(size);
    send_read_segment();
    return;
  }

  if (c.command_id != static_cast<uint8_t>(SdoCommandId::kWriteByIndex)) {
    send_abort(c.transaction_id, c.command_id, sdo_abort::kUnknownCommand);
    return;
  }
  switch (c.segmentation) {
    case SdoSegmentation::kExpedited:
      in_write_ = false;
      size_ = 0;
      expected_ = c.payload.size();
      break;
    case SdoSegmentation::kInitiate:
      if (c.total_size > buffer_.size()) {
        send_abort(c.transaction_id, c.command_id, sdo_abort::kOutOfMemory);
        return;
      }
      in_write_ = true;
      transaction_ = c.transaction_id;
      size_ = 0;
      expected_ = c.total_size;
      break;
    case SdoSegmentation::kSegment:
    case SdoSegmentation::kComplete:
      if (!in_write_ || c.transaction_id != transaction_) {
        send_abort(c.transaction_id, c.command_id, sdo_abort::kGeneral);
        return;
      }
      break;
  }
  if (size_ + c.payload.size() > expected_) {
    send_abort(c.transaction_id, c.command_id, sdo_abort::kTypeLength);
    return;
  }
  std::copy(c.payload.begin(), c.payload.end(), buffer_.begin() + size_);
  size_ += c.payload.size();
  if (c.segmentation == SdoSegmentation::kInitiate || c.segmentation == SdoSegmentation::kSegment) {
    send_frame(false, {});  // acknowledge the segment
    return;
  }
  in_write_ = false;
  if (size_ != expected_ || size_ < kIndexHeader) {
    send_abort(c.transaction_id, c.command_id, sdo_abort::kTypeLength);
    return;
  }
  const uint16_t index = load_le16(buffer_.data());
  const uint8_t subindex = buffer_[2];
  const uint32_t code = objects_.write_object(
      index, subindex,
      std::span<const uint8_t>(buffer_.data() + kIndexHeader, size_ - kIndexHeader));
  if (code != 0) {
    send_abort(c.transaction_id, c.command_id, code);
    return;
  }
  send_frame(true, rsp);
}

void SdoServer::send_read_segment() noexcept {
  SdoCommand rsp;
  rsp.transaction_id = transaction_;
  rsp.response = true;
  rsp.command_id = static_cast<uint8_t>(SdoCommandId::kReadByIndex);
  const SdoSegmenter::Segment seg = segmenter_.next(config_.max_segment);
  rsp.segmentation = seg.segmentation;
  rsp.total_size = seg.total_size;
  rsp.payload = std::span<const uint8_t>(buffer_.data() + seg.offset, seg.length);
  in_read_ = !segmenter_.done();
  send_frame(true, rsp);
}

}  // namespace ds1928::powerlink
