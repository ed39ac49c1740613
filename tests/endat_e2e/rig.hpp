// A daemon without Daemon: SimulatedBus (optionally behind a test decorator) + CycleWork run by a
// cycle thread + shm::Publisher + RegisterClient + EnDatService + control::Server on a temporary
// socket, all on their real threads. Tests talk to it over the socket like ds1928ctl does.
#pragma once

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <functional>
#include <future>
#include <memory>
#include <random>
#include <string>
#include <thread>

#include "../control/control_test_util.hpp"
#include "../flatstream/lossy_bus.hpp"
#include "control/asio.hpp"
#include "control/control_server.hpp"
#include "cycle_work.hpp"
#include "endat/command.hpp"
#include "endat_service.hpp"
#include "flatstream/channel.hpp"
#include "register_client.hpp"
#include "shm/publisher.hpp"
#include "sim/simulated_bus.hpp"
#include "support/wait.hpp"

namespace ds1928::endat_test {

using nlohmann::json;

// Forwards everything to the simulated bus; subclasses change what crosses per cycle.
class BusDecorator : public BusDriver {
 public:
  explicit BusDecorator(BusDriver& inner) : inner_(inner) {}
  [[nodiscard]] std::string_view name() const noexcept override { return inner_.name(); }
  [[nodiscard]] std::error_code start() override { return inner_.start(); }
  void stop() noexcept override { inner_.stop(); }
  [[nodiscard]] BusState state() const noexcept override { return inner_.state(); }
  [[nodiscard]] bool submit(const RegisterRequest& r) noexcept override { return inner_.submit(r); }
  [[nodiscard]] bool poll(RegisterResult& out) noexcept override { return inner_.poll(out); }

 protected:
  BusDriver& inner_;
};

// Drops, delays and repeats the whole register image per cycle and direction (the Flatstream
// random-bus figures: deliver 86 %, drop 6 %, delay 1–4 cycles 4 %, repeat 4 %), plus outages.
class LossyBus final : public BusDecorator {
 public:
  LossyBus(BusDriver& inner, uint32_t seed) : BusDecorator(inner), rng_(seed) {}
  ExchangeResult exchange(std::span<AxisIo> axes, int64_t start_ns,
                          uint64_t index) noexcept override {
    using flatstream::test::BusEvent;
    if (scratch_.size() != axes.size()) {
      scratch_.resize(axes.size());
      out_.resize(axes.size());
      in_.resize(axes.size());
    }
    for (std::size_t i = 0; i < axes.size(); ++i) {
      const auto [e, k] = event();
      out_[i].write(axes[i].outputs, t_, e, k);
      scratch_[i].outputs = out_[i].read(t_);
    }
    const ExchangeResult r = inner_.exchange(scratch_, start_ns, index);
    for (std::size_t i = 0; i < axes.size(); ++i) {
      const auto [e, k] = event();
      in_[i].write(scratch_[i].inputs, t_, e, k);
      axes[i].inputs = in_[i].read(t_);
      axes[i].inputs_fresh = scratch_[i].inputs_fresh;
      axes[i].rx_time_ns = scratch_[i].rx_time_ns;
    }
    ++t_;
    return r;
  }

 private:
  std::pair<flatstream::test::BusEvent, unsigned> event() {
    using flatstream::test::BusEvent;
    // Every 1.5 s an outage of 250 cycles, longer than the Flatstream timeout (200 cycles):
    // the channel resynchronises and messages in flight fail as unconfirmed / timeout.
    if (t_ % 1500 >= 1000 && t_ % 1500 < 1250) return {BusEvent::Drop, 0};
    const unsigned p = std::uniform_int_distribution<unsigned>(0, 99)(rng_);
    if (p < 86) return {BusEvent::Deliver, 0};
    if (p < 92) return {BusEvent::Drop, 0};
    if (p < 96) return {BusEvent::Delay, std::uniform_int_distribution<unsigned>(1, 4)(rng_)};
    return {BusEvent::Repeat, 0};
  }
  std::mt19937 rng_;
  uint64_t t_ = 1;
  std::vector<AxisIo> scratch_;
  std::vector<flatstream::test::LossyLink<ModuleOutputs>> out_;
  std::vector<flatstream::test::LossyLink<ModuleInputs>> in_;
};

// Replaces axis 0's Flatstream peer with a scripted module: it answers reads from a small memory
// (default word = MRS << 8 | parameter), stores writes, and can be told to answer the next
// commands wrongly (wrong MRS echo, a byte short), late, or not at all.
class ScriptedModule final : public BusDecorator {
 public:
  enum class Fault : int { None, WrongMrsEcho, Truncated, Silent, Late };
  explicit ScriptedModule(BusDriver& inner)
      : BusDecorator(inner), channel_(flatstream::ModuleConfig{7, 7, 0, 1, 0, 200}) {}

  // The next `n` commands get `fault` (Late: the reply comes `late_cycles` cycles after).
  void inject(Fault fault, int n, uint32_t late_cycles = 0) {
    late_cycles_.store(late_cycles);
    fault_.store(static_cast<int>(fault));
    faulty_.store(n);
  }
  // Commands the scripted module received whose parameter byte was `param`.
  [[nodiscard]] int received_with_param(uint8_t param) const { return seen_[param].load(); }
  [[nodiscard]] int commands() const { return commands_.load(); }

  ExchangeResult exchange(std::span<AxisIo> axes, int64_t start_ns,
                          uint64_t index) noexcept override {
    const ExchangeResult r = inner_.exchange(axes, start_ns, index);
    if (axes.empty()) return r;
    ++cycle_;
    for (std::size_t i = 0; i < pending_count_;) {
      if (pending_[i].due <= cycle_) {
        (void)channel_.submit(pending_[i].reply.span(), 1);
        pending_[i] = pending_[--pending_count_];
      } else {
        ++i;
      }
    }
    const auto frame = channel_.step(flatstream::output_frame(axes[0].outputs),
                                     static_cast<uint64_t>(start_ns / 1000));
    flatstream::apply(frame, axes[0].inputs);
    flatstream::Message m;
    while (channel_.take_received(m)) answer(m);
    return r;
  }

 private:
  void answer(const flatstream::Message& m) {
    ++commands_;
    auto request = endat::decode_request(m.payload());
    if (!request) return;
    const endat::Request& q = *request;
    seen_[q.parameter].fetch_add(1);
    const std::size_t key = static_cast<std::size_t>(q.mrs) * 256 + q.parameter;
    if (endat::is_write(q.command)) memory_[key] = static_cast<int32_t>(q.value);
    const uint16_t word = memory_[key] >= 0 ? static_cast<uint16_t>(memory_[key])
                                            : static_cast<uint16_t>(q.mrs << 8 | q.parameter);
    const uint16_t words[4] = {word, word, word, word};
    endat::ReplyMessage reply = endat::encode_reply(q, words);
    uint64_t due = cycle_;
    Fault fault = Fault::None;
    if (faulty_.load() > 0) {
      faulty_.fetch_sub(1);
      fault = static_cast<Fault>(fault_.load());
    }
    switch (fault) {
      case Fault::None:
        break;
      case Fault::WrongMrsEcho:
        reply.bytes[1] = static_cast<uint8_t>(reply.bytes[1] + 2);
        break;
      case Fault::Truncated:
        --reply.size;
        break;
      case Fault::Silent:
        return;
      case Fault::Late:
        due += late_cycles_.load();
        break;
    }
    if (pending_count_ < pending_.size()) pending_[pending_count_++] = {due, reply};
  }

  struct Pending {
    uint64_t due = 0;
    endat::ReplyMessage reply;
  };
  flatstream::ModuleChannel channel_;
  std::array<Pending, 16> pending_{};
  std::size_t pending_count_ = 0;
  uint64_t cycle_ = 0;
  std::array<int32_t, 65536> memory_ = [] {
    std::array<int32_t, 65536> a{};
    a.fill(-1);
    return a;
  }();
  std::array<std::atomic<int>, 256> seen_{};
  std::atomic<int> commands_{0};
  std::atomic<int> fault_{0};
  std::atomic<int> faulty_{0};
  std::atomic<uint32_t> late_cycles_{0};
};

enum class Peer { Simulated, Lossy, Scripted };

struct RigOptions {
  Peer peer = Peer::Simulated;
  uint32_t period_us = 1000;
  uint32_t command_timeout_ms = 2000;
  uint32_t seed = 1;
};

class Rig {
 public:
  explicit Rig(RigOptions o = {}) : options_(o) {
    static std::atomic<int> serial{0};
    const int n = ++serial;
    config_.cycle.period_us = o.period_us;
    AxisConfig axis;
    axis.name = "axis0";
    axis.command_timeout_ms = o.command_timeout_ms;
    config_.axes.push_back(axis);
    config_.shm.name = "/ds1928-e2e-" + std::to_string(getpid()) + "-" + std::to_string(n);
    config_.socket.path = control::test::temp_socket_path("endat");
    socket_dir_.dir = std::filesystem::path(config_.socket.path).parent_path();
    config_.socket.privileged_group = "";
    sim_ = std::make_unique<sim::SimulatedBus>(config_.axes, config_.simulated);
    switch (o.peer) {
      case Peer::Simulated:
        bus_ = sim_.get();
        break;
      case Peer::Lossy:
        decorator_ = std::make_unique<LossyBus>(*sim_, o.seed);
        bus_ = decorator_.get();
        break;
      case Peer::Scripted:
        decorator_ = std::make_unique<ScriptedModule>(*sim_);
        bus_ = decorator_.get();
        break;
    }
    if (auto ec = bus_->start()) throw std::runtime_error("bus start: " + ec.message());
    if (auto ec = publisher_.open(config_.shm, 1, uint64_t{o.period_us} * 1000))
      throw std::runtime_error("shm open: " + ec.message());
    work_ = std::make_unique<CycleWork>(config_, *bus_, publisher_);
    registers_ = std::make_unique<RegisterClient>(io_, *bus_);
    service_ = std::make_unique<EnDatService>(io_, *work_, *registers_, config_);
    server_ = std::make_unique<control::Server>(io_, config_.socket);
    service_->register_commands(*server_);
    if (auto ec = server_->start()) throw std::runtime_error("server start: " + ec.message());
    cycle_thread_ = std::thread([this] { cycle_loop(); });
    registers_->start(std::chrono::microseconds(o.period_us));
    service_->start();
    io_thread_ = std::thread([this] { io_.run(); });
  }

  ~Rig() {
    run([this] {
      service_->stop();
      registers_->stop();
      server_->stop();
    });
    work_guard_.reset();
    io_.stop();
    io_thread_.join();
    stop_.store(true);
    cycle_thread_.join();
    publisher_.close();
  }

  // Runs `f` on the io thread and waits for its result.
  template <class F>
  auto run(F f) -> decltype(f()) {
    std::packaged_task<decltype(f())()> task(std::move(f));
    auto result = task.get_future();
    boost::asio::post(io_, [&task] { task(); });
    return result.get();
  }

  [[nodiscard]] const std::string& socket_path() const { return config_.socket.path; }
  [[nodiscard]] const std::string& shm_name() const { return config_.shm.name; }
  [[nodiscard]] EnDatService& service() { return *service_; }
  [[nodiscard]] CycleWork& work() { return *work_; }
  [[nodiscard]] ScriptedModule& scripted() { return static_cast<ScriptedModule&>(*decorator_); }
  [[nodiscard]] uint64_t cycles() const { return cycles_.load(); }
  [[nodiscard]] EnDatService::Counters counters() {
    return run([this] { return service_->counters(0); });
  }
  // Waits for the identification (it runs at start).
  bool wait_identified() {
    return ds1928::test::wait_until(
        [this] { return run([this] { return service_->identification(0).has_value(); }); });
  }

 private:
  void cycle_loop() {
    using clock = std::chrono::steady_clock;
    auto next = clock::now();
    uint64_t index = 0;
    while (!stop_.load()) {
      CycleContext ctx;
      ctx.index = index++;
      ctx.start_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(next.time_since_epoch()).count();
      ctx.woke_ns = ctx.start_ns;
      work_->run_cycle(ctx);
      cycles_.fetch_add(1);
      next += std::chrono::microseconds(options_.period_us);
      std::this_thread::sleep_until(next);
      if (clock::now() - next > std::chrono::milliseconds(20))
        next = clock::now();  // loaded machine
    }
  }

  // Removes the socket's directory last, also when the constructor throws half-way.
  struct RemoveDir {
    std::filesystem::path dir;
    ~RemoveDir() {
      std::error_code ec;
      if (!dir.empty()) std::filesystem::remove_all(dir, ec);
    }
  };

  RigOptions options_;
  DaemonConfig config_;
  RemoveDir socket_dir_;
  std::unique_ptr<sim::SimulatedBus> sim_;
  std::unique_ptr<BusDriver> decorator_;
  BusDriver* bus_ = nullptr;
  shm::Publisher publisher_;
  std::unique_ptr<CycleWork> work_;
  boost::asio::io_context io_;
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>>
      work_guard_{boost::asio::make_work_guard(io_)};
  std::unique_ptr<RegisterClient> registers_;
  std::unique_ptr<EnDatService> service_;
  std::unique_ptr<control::Server> server_;
  std::thread cycle_thread_;
  std::thread io_thread_;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> cycles_{0};
};

inline json call(control::test::LineClient& c, json request) {
  return c.request(request);
}

}  // namespace ds1928::endat_test
