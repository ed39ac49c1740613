// The daemon's log queue: bounded, and a stalled writer (a journal or terminal that stops
// reading) never blocks a caller — the oldest messages are dropped instead.
#include "service/logging.hpp"

#include <spdlog/async.h>
#include <spdlog/sinks/base_sink.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <condition_variable>
#include <future>
#include <mutex>
#include <string>

namespace {

// A sink that blocks in its first message until released: the writer thread stalls there.
class StalledSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  void release() {
    {
      std::lock_guard lock(gate_);
      released_ = true;
    }
    cv_.notify_all();
  }
  [[nodiscard]] std::size_t written() const { return written_.load(); }
  // Waits (bounded) until `payload` is written; the last payload written.
  [[nodiscard]] std::string wait_for(const std::string& payload) {
    std::unique_lock lock(gate_);
    cv_.wait_for(lock, std::chrono::seconds(30), [&] { return last_ == payload; });
    return last_;
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    std::unique_lock lock(gate_);
    cv_.wait(lock, [this] { return released_; });
    last_.assign(msg.payload.data(), msg.payload.size());
    ++written_;
    cv_.notify_all();
  }
  void flush_() override {}

 private:
  std::mutex gate_;
  std::condition_variable cv_;
  bool released_ = false;
  std::string last_;
  std::atomic<std::size_t> written_{0};
};

}  // namespace

TEST_CASE("a stalled log writer drops the oldest messages and never blocks the caller",
          "[control][logging]") {
  auto logger = ds1928::control::setup_logging(spdlog::level::info,
                                               ds1928::control::LogSink::Console, "queue-test");
  logger->flush_on(spdlog::level::off);
  for (auto& s : logger->sinks()) s->set_level(spdlog::level::off);  // keep the test output clean
  auto stalled = std::make_shared<StalledSink>();
  logger->sinks().push_back(stalled);

  // 8192 is the queue's capacity (logging.cpp); 3 × that from a caller that must not wait.
  constexpr std::size_t kCapacity = 8192;
  constexpr std::size_t kMessages = 3 * kCapacity;
  auto done = std::async(std::launch::async, [&] {
    for (std::size_t i = 0; i < kMessages; ++i) logger->info("message {}", i);
  });
  const bool finished = done.wait_for(std::chrono::seconds(60)) == std::future_status::ready;
  const std::size_t overruns = spdlog::thread_pool()->overrun_counter();
  const std::size_t queued = spdlog::thread_pool()->queue_size();
  stalled->release();
  done.wait();
  REQUIRE(finished);  // every call returned although nothing was written meanwhile
  // The writer holds at most one message in the stalled sink; the queue the rest.
  CHECK(queued <= kCapacity);
  CHECK(overruns + queued + 1 >= kMessages);
  CHECK(overruns >= kMessages - kCapacity - 1);

  // The newest messages are the ones kept.
  const std::string newest = "message " + std::to_string(kMessages - 1);
  CHECK(stalled->wait_for(newest) == newest);
  CHECK(stalled->written() <= kCapacity + 1);
  ds1928::control::shutdown_logging();
}
