// The virtual CAN bus as a test transport: broadcast semantics, filters, stamps from an injected
// clock, every fault it can inject, overrun accounting, the cross-process bus over shared
// memory, and an allocation-free send/receive path.
#include "can/virtual_bus.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <barrier>
#include <catch2/catch.hpp>
#include <string>
#include <thread>

#include "support/alloc_counter.hpp"
#include "vbus_test_support.hpp"

using namespace ds1928::canio;
using namespace ds1928::canio::test;

namespace {

CanFrame data_frame(uint32_t id, uint8_t tag) {
  const uint8_t bytes[8] = {tag, 1, 2, 3, 4, 5, 6, 7};
  return make_standard_frame(id, bytes);
}

}  // namespace

TEST_CASE("every port sees the other ports' frames, never its own", "[canio][vbus]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(clock.options());
  auto a = port(bus), b = port(bus), c = port(bus);
  REQUIRE(a->send(data_frame(0x181, 1)).sent());
  clock.advance_ms(1);
  REQUIRE(b->send(data_frame(0x281, 2)).sent());
  auto at_a = drain(*a), at_b = drain(*b), at_c = drain(*c);
  REQUIRE(at_a.size() == 1);
  CHECK(at_a[0].id == 0x281);
  REQUIRE(at_b.size() == 1);
  CHECK(at_b[0].id == 0x181);
  REQUIRE(at_c.size() == 2);
  CHECK(same_content(at_c[0], data_frame(0x181, 1)));
  CHECK(same_content(at_c[1], data_frame(0x281, 2)));
  // Stamps come from the bus clock at the time the frame went on the bus.
  CHECK(at_c[0].rx_time_ns == 1'000'000'000);
  CHECK(at_c[1].rx_time_ns == 1'001'000'000);
  CHECK(at_c[0].rx_clock == RxClock::VirtualBus);
  CHECK(c->counters().rx_frames == 2);
  CHECK(a->counters().tx_frames == 1);
  // A port opened later sees only what is sent from then on.
  auto d = port(bus);
  CHECK(drain(*d).empty());
}

TEST_CASE("filters pass exactly the listed identifiers, error frames only when subscribed",
          "[canio][vbus]") {
  auto bus = VirtualCanBus::create_local();
  auto tx = port(bus), rx = port(bus);
  const CanIdFilter ids[] = {{0x181, false}, {0x1234567, true}};
  REQUIRE_FALSE(rx->set_filters(ids));
  REQUIRE(tx->send(data_frame(0x181, 1)).sent());
  REQUIRE(tx->send(data_frame(0x182, 2)).sent());  // not listed
  CanFrame ext = data_frame(0x1234567 & 0x7FF, 3);
  ext.id = 0x1234567;
  ext.extended = true;
  REQUIRE(tx->send(ext).sent());
  CanFrame std_same = data_frame(0x567, 4);  // same low bits, standard: not listed
  REQUIRE(tx->send(std_same).sent());
  auto got = drain(*rx);
  REQUIRE(got.size() == 2);
  CHECK(got[0].id == 0x181);
  CHECK((got[1].id == 0x1234567 && got[1].extended));

  std::array<CanIdFilter, kMaxFilters + 1> too_many{};
  CHECK(rx->set_filters(too_many) == CanError::kTooManyFilters);
  const CanIdFilter bad[] = {{0x800, false}};
  CHECK(rx->set_filters(bad) == CanError::kInvalidFrame);

  CanErrorEvent prot;
  prot.protocol = true;
  prot.protocol_type = err_prot::kForm;
  REQUIRE(rx->inject_error(prot));
  CHECK(drain(*rx).empty());  // not subscribed
  CHECK(rx->counters().protocol_errors == 1);
  // The default mask leaves protocol violations out: the kernel reports every bus error as
  // CAN_ERR_PROT | CAN_ERR_BUSERROR, and they must not wake the cycle.
  REQUIRE_FALSE(rx->set_error_mask(kDefaultErrorMask));
  REQUIRE(rx->inject_error(prot));
  CHECK(drain(*rx).empty());
  REQUIRE_FALSE(rx->set_error_mask(kDefaultErrorMask | err_class::kProtocol));
  REQUIRE(rx->inject_error(prot));
  got = drain(*rx);
  REQUIRE(got.size() == 1);
  REQUIRE(got[0].error);
  auto e = decode_error_frame(got[0]);
  REQUIRE(e);
  CHECK(e->protocol_type == err_prot::kForm);
  CHECK(rx->state() == CanState::ErrorActive);
}

TEST_CASE("injected controller errors move the state as the kernel's would", "[canio][vbus]") {
  auto bus = VirtualCanBus::create_local();
  auto p = port(bus);
  REQUIRE_FALSE(p->set_error_mask(kDefaultErrorMask));
  CanErrorEvent warn;
  warn.controller = true;
  warn.controller_status = err_ctrl::kTxWarning;
  REQUIRE(p->inject_error(warn));
  (void)drain(*p);
  CHECK(p->state() == CanState::ErrorWarning);
  CanErrorEvent passive = warn;
  passive.controller_status = err_ctrl::kTxPassive;
  REQUIRE(p->inject_error(passive));
  (void)drain(*p);
  CHECK(p->state() == CanState::ErrorPassive);
  CHECK(p->send(data_frame(1, 1)).sent());  // passive nodes still send
  CanErrorEvent active = warn;
  active.controller_status = err_ctrl::kActive;
  REQUIRE(p->inject_error(active));
  (void)drain(*p);
  CHECK(p->state() == CanState::ErrorActive);
  CHECK(p->counters().controller_errors == 3);
}

TEST_CASE("bus-off: sends refused, restarted after restart-ms, error-active again",
          "[canio][vbus]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(clock.options());
  VirtualPortOptions o;
  o.restart_ms = 100;
  auto p = port(bus, o), peer = port(bus);
  REQUIRE_FALSE(p->set_error_mask(kDefaultErrorMask));
  REQUIRE(p->inject_bus_off());
  CHECK(p->state() == CanState::BusOff);
  const auto refused = p->send(data_frame(0x201, 1));
  CHECK(refused.status == SendStatus::BusOff);
  auto got = drain(*p);
  REQUIRE(got.size() == 1);
  CHECK(decode_error_frame(got[0])->bus_off);
  // A bus-off controller does not receive.
  REQUIRE(peer->send(data_frame(0x181, 2)).sent());
  CHECK(drain(*p).empty());
  CHECK(p->fault_counters().missed_off_bus == 1);

  clock.advance_ms(99);
  CHECK(drain(*p).empty());
  CHECK(p->state() == CanState::BusOff);
  clock.advance_ms(1);
  got = drain(*p);
  REQUIRE(got.size() == 1);
  auto e = decode_error_frame(got[0]);
  REQUIRE(e);
  CHECK(e->restarted);
  CHECK(p->state() == CanState::ErrorActive);
  CHECK(p->send(data_frame(0x201, 3)).sent());
  const auto c = p->counters();
  CHECK(c.bus_off_events == 1);
  CHECK(c.restarts == 1);
  CHECK(c.tx_bus_off == 1);
}

TEST_CASE("a port that only sends through bus-off and restart reports both, in order",
          "[canio][vbus]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(clock.options());
  auto p = port(bus);  // restart-ms 100
  REQUIRE_FALSE(p->set_error_mask(kDefaultErrorMask));
  REQUIRE(p->inject_bus_off());
  CHECK(p->send(data_frame(1, 1)).status == SendStatus::BusOff);
  clock.advance_ms(150);
  CHECK(p->send(data_frame(1, 2)).sent());  // restarted by the send path
  auto got = drain(*p);
  REQUIRE(got.size() == 2);
  CHECK(decode_error_frame(got[0])->bus_off);
  CHECK(decode_error_frame(got[1])->restarted);
  CHECK(p->state() == CanState::ErrorActive);  // the late bus-off frame does not undo the restart
}

TEST_CASE("an error broadcast by one port reaches every other port's controller", "[canio][vbus]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(clock.options());
  auto sim = port(bus), daemon = port(bus), quiet = port(bus);
  REQUIRE_FALSE(daemon->set_error_mask(kDefaultErrorMask));
  CanErrorEvent off;
  off.bus_off = true;
  REQUIRE(sim->broadcast_error(off));
  auto got = drain(*daemon);
  REQUIRE(got.size() == 1);
  CHECK(decode_error_frame(got[0])->bus_off);
  CHECK(daemon->state() == CanState::BusOff);
  CHECK(daemon->send(data_frame(0x201, 1)).status == SendStatus::BusOff);
  CHECK(drain(*quiet).empty());  // not subscribed: no frame, but the state changed all the same
  CHECK(quiet->state() == CanState::BusOff);
  CHECK(sim->state() == CanState::ErrorActive);  // not its own
  clock.advance_ms(100);
  got = drain(*daemon);
  REQUIRE(got.size() == 1);
  CHECK(decode_error_frame(got[0])->restarted);
  CHECK(daemon->state() == CanState::ErrorActive);
  // A frame with no room in the caller's span waits for the next call.
  CanErrorEvent passive;
  passive.controller = true;
  passive.controller_status = err_ctrl::kRxPassive;
  REQUIRE(sim->send(data_frame(0x181, 1)).sent());
  REQUIRE(sim->broadcast_error(passive));
  std::array<CanFrame, 1> one;
  REQUIRE(daemon->receive(one, 0).count == 1);
  CHECK(one[0].id == 0x181);
  REQUIRE(daemon->receive(one, 0).count == 1);
  CHECK(one[0].error);
  CHECK(daemon->state() == CanState::ErrorPassive);
}

TEST_CASE("bus-off without restart-ms waits for restart()", "[canio][vbus]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(clock.options());
  VirtualPortOptions o;
  o.restart_ms = 0;
  auto p = port(bus, o);
  REQUIRE_FALSE(p->set_error_mask(err_class::kBusOff | err_class::kRestarted));
  REQUIRE(p->inject_bus_off());
  (void)drain(*p);
  clock.advance_ms(10'000);
  CHECK(drain(*p).empty());
  CHECK(p->send(data_frame(1, 1)).status == SendStatus::BusOff);
  p->restart();
  CHECK(p->send(data_frame(1, 1)).sent());  // the restart is taken by the next call
  auto got = drain(*p);
  REQUIRE(got.size() == 1);
  CHECK(decode_error_frame(got[0])->restarted);
  auto info = p->query_interface();
  REQUIRE(info);
  CHECK(info->state == CanState::ErrorActive);
  CHECK(info->restart_ms == 0);
}

TEST_CASE("random loss is seeded and close to its probability", "[canio][vbus]") {
  auto run = [](uint64_t seed, std::vector<uint8_t>* pattern) {
    auto bus = VirtualCanBus::create_local(VirtualBusOptions{1 << 12, {}});
    auto tx = port(bus), rx = port(bus);
    rx->set_loss(FaultDirection::Rx, 0.05, seed);
    uint64_t received = 0;
    std::array<CanFrame, 64> buf;
    for (int i = 0; i < 100'000; ++i) {
      REQUIRE(tx->send(data_frame(0x181, static_cast<uint8_t>(i))).sent());
      auto r = rx->receive(buf, 0);
      REQUIRE(r.count <= 1);
      received += r.count;
      if (pattern && i < 2000) pattern->push_back(static_cast<uint8_t>(r.count));
    }
    CHECK(rx->fault_counters().rx_lost + received == 100'000);
    return received;
  };
  std::vector<uint8_t> p1, p2, p3;
  const auto got = run(42, &p1);
  CHECK(got > 94'500);
  CHECK(got < 95'500);
  CHECK(run(42, &p2) == got);
  CHECK(p1 == p2);  // same seed, same frames lost
  (void)run(43, &p3);
  CHECK(p1 != p3);
}

TEST_CASE("drop the next k frames with an identifier, on receive or on send", "[canio][vbus]") {
  auto bus = VirtualCanBus::create_local();
  auto tx = port(bus), rx = port(bus), other = port(bus);
  rx->drop_next(FaultDirection::Rx, 0x181, 2);
  for (uint8_t i = 0; i < 4; ++i) {
    REQUIRE(tx->send(data_frame(0x181, i)).sent());
    REQUIRE(tx->send(data_frame(0x281, i)).sent());
  }
  auto got = drain(*rx);
  REQUIRE(got.size() == 6);
  CHECK(got[0].id == 0x281);
  CHECK(got[1].id == 0x281);
  CHECK((got[2].id == 0x181 && got[2].data[0] == 2));
  CHECK(drain(*other).size() == 8);  // only rx's copy was lost
  tx->drop_next(FaultDirection::Tx, 0x281, 1);
  REQUIRE(tx->send(data_frame(0x281, 9)).sent());  // the sender cannot tell
  REQUIRE(tx->send(data_frame(0x281, 10)).sent());
  CHECK(drain(*other).size() == 1);
  CHECK(tx->fault_counters().tx_lost == 1);
}

TEST_CASE("delayed delivery by receive polls and by time", "[canio][vbus]") {
  FakeClock clock;
  auto bus = VirtualCanBus::create_local(clock.options());
  auto tx = port(bus), rx = port(bus);
  std::array<CanFrame, 8> buf;
  SECTION("after N polls, stamped at delivery") {
    rx->set_delay_polls(2);
    REQUIRE(tx->send(data_frame(0x181, 1)).sent());
    CHECK(rx->receive(buf, 0).count == 0);
    clock.advance_ms(1);
    CHECK(rx->receive(buf, 0).count == 0);
    clock.advance_ms(1);
    REQUIRE(rx->receive(buf, 0).count == 1);
    CHECK(buf[0].rx_time_ns == 1'002'000'000);
  }
  SECTION("after a time, stamped at the delayed arrival") {
    rx->set_delay_ns(5'000'000);
    REQUIRE(tx->send(data_frame(0x181, 1)).sent());
    clock.advance_ms(4);
    CHECK(rx->receive(buf, 0).count == 0);
    clock.advance_ms(3);
    REQUIRE(rx->receive(buf, 0).count == 1);
    CHECK(buf[0].rx_time_ns == 1'005'000'000);
    rx->set_delay_ns(0);
    REQUIRE(tx->send(data_frame(0x181, 2)).sent());
    REQUIRE(rx->receive(buf, 0).count == 1);
    CHECK(buf[0].data[0] == 2);
  }
  CHECK(rx->fault_counters().delayed >= 1);
}

TEST_CASE("a full TX queue and a down interface are reported, never retried", "[canio][vbus]") {
  auto bus = VirtualCanBus::create_local();
  auto tx = port(bus), rx = port(bus);
  tx->fail_next_sends(2, SendStatus::QueueFull);
  auto r = tx->send(data_frame(0x181, 1));
  CHECK(r.status == SendStatus::QueueFull);
  CHECK(r.error_number == ENOBUFS);
  CHECK(tx->send(data_frame(0x181, 2)).status == SendStatus::QueueFull);
  CHECK(tx->send(data_frame(0x181, 3)).sent());
  auto got = drain(*rx);
  REQUIRE(got.size() == 1);
  CHECK(got[0].data[0] == 3);
  CHECK(tx->counters().tx_queue_full == 2);

  CanFrame bad = data_frame(0x800, 1);
  bad.id = 0x800;
  CHECK(tx->send(bad).status == SendStatus::InvalidFrame);

  rx->set_up(false);
  std::array<CanFrame, 4> buf;
  CHECK(rx->receive(buf, 0).error == CanError::kInterfaceDown);
  CHECK(rx->state() == CanState::Down);
  tx->set_up(false);
  CHECK(tx->send(data_frame(0x181, 4)).status == SendStatus::InterfaceDown);
  tx->set_up(true);
  rx->set_up(true);
  REQUIRE(tx->send(data_frame(0x181, 5)).sent());
  CHECK(drain(*rx).size() == 1);
}

TEST_CASE("a reader lapped by the writers counts the lost frames and resumes", "[canio][vbus]") {
  auto bus = VirtualCanBus::create_local(VirtualBusOptions{16, {}});
  auto tx = port(bus), rx = port(bus);
  for (int i = 0; i < 40; ++i) REQUIRE(tx->send(data_frame(0x181, static_cast<uint8_t>(i))).sent());
  auto got = drain(*rx);
  REQUIRE_FALSE(got.empty());
  CHECK(got.back().data[0] == 39);
  CHECK(got.size() + rx->counters().rx_kernel_drops == 40);
  CHECK(rx->counters().rx_kernel_drops >= 24);
}

TEST_CASE("a blocking receive wakes for a frame from another thread", "[canio][vbus]") {
  auto bus = VirtualCanBus::create_local();
  auto tx = port(bus), rx = port(bus);
  std::barrier sync(2);
  std::thread sender([&] {
    sync.arrive_and_wait();
    REQUIRE(tx->send(data_frame(0x181, 7)).sent());
  });
  const int64_t deadline = deadline_in(30);
  sync.arrive_and_wait();
  std::array<CanFrame, 4> buf;
  auto r = rx->receive(buf, deadline);
  sender.join();
  REQUIRE(r.count == 1);
  CHECK(buf[0].data[0] == 7);
}

TEST_CASE("two processes talk over a shared virtual bus", "[canio][vbus][process]") {
  const std::string name = "test-" + std::to_string(getpid());
  REQUIRE_FALSE(VirtualCanBus::remove_shared(name));
  auto bus = VirtualCanBus::open_shared(name, {}, true);
  REQUIRE(bus);
  auto me = port(*bus);
  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // The node: answers every 0x080 frame with 0x181 carrying the same first byte + 1.
    auto p = node_port(name, {}, 0x080, data_frame(0x700, 0));
    std::array<CanFrame, 8> buf;
    for (int answered = 0; answered < 100;) {
      auto r = p->receive(buf, INT64_MAX);
      if (r.error) _exit(6);
      for (std::size_t i = 0; i < r.count; ++i, ++answered)
        if (!p->send(data_frame(0x181, static_cast<uint8_t>(buf[i].data[0] + 1))).sent()) _exit(7);
    }
    _exit(0);
  }
  const int64_t deadline = deadline_in(60);
  expect_node_up(*me, 0x700, deadline);
  std::array<CanFrame, 8> buf;
  int answered = 0;
  for (int i = 0; i < 100; ++i) {
    REQUIRE(me->send(data_frame(0x080, static_cast<uint8_t>(i))).sent());
    auto a = me->receive(buf, deadline);
    REQUIRE(a.count == 1);
    CHECK(buf[0].id == 0x181);
    answered += buf[0].data[0] == static_cast<uint8_t>(i + 1);
  }
  CHECK(answered == 100);
  expect_node_done(child);
  // A bus of another ring size under the same name is refused.
  auto other = VirtualCanBus::open_shared(name, VirtualBusOptions{64, {}});
  CHECK(other.error() == CanError::kVirtualBusMismatch);
  CHECK(VirtualCanBus::open_shared("bad/name").error() == CanError::kInterfaceNameInvalid);
}

TEST_CASE("a bus another user left behind: the error names its file, owner and the fix",
          "[canio][vbus][process]") {
  const std::string name = "test-owner-" + std::to_string(getpid());
  const std::string file = "/dev/shm/ds1928-vcan." + name;
  REQUIRE_FALSE(VirtualCanBus::remove_shared(name));
  auto bus = VirtualCanBus::open_shared(name, {}, true);
  REQUIRE(bus);
  const std::string text =
      VirtualCanBus::open_error_text(name, std::error_code(EACCES, std::system_category()));
  CHECK(text.find(file + " belongs to uid " + std::to_string(getuid())) != std::string::npos);
  CHECK(text.find("mode 0600") != std::string::npos);
  CHECK(text.find("(rm " + file + ")") != std::string::npos);
  // Any other error is its message alone.
  CHECK(VirtualCanBus::open_error_text(name, std::error_code(ENOMEM, std::system_category())) ==
        std::error_code(ENOMEM, std::system_category()).message());
  if (getuid() == 0) {
    // The real refusal: another uid opening root's bus gets EACCES, and the text above.
    const pid_t child = fork();
    REQUIRE(child >= 0);
    if (child == 0) {
      if (setresgid(65534, 65534, 65534) != 0 || setresuid(65534, 65534, 65534) != 0) _exit(2);
      auto other = VirtualCanBus::open_shared(name);
      _exit(!other && other.error() == std::error_code(EACCES, std::system_category()) ? 0 : 1);
    }
    int status = 0;
    REQUIRE(waitpid(child, &status, 0) == child);
    CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 0));
  }
}

TEST_CASE("send and receive allocate nothing and take no lock", "[canio][vbus][alloc]") {
  auto bus = VirtualCanBus::create_local();
  auto tx = port(bus), rx = port(bus);
  const CanIdFilter ids[] = {{0x181, false}};
  REQUIRE_FALSE(rx->set_filters(ids));
  REQUIRE_FALSE(rx->set_error_mask(kDefaultErrorMask));
  rx->set_loss(FaultDirection::Rx, 0.05, 1);
  std::array<CanFrame, 8> buf;
  uint64_t received = 0;
  ds1928::test::HeapCounts counts;
  {
    ds1928::test::ScopedCounting counting;
    for (int i = 0; i < 10'000; ++i) {
      (void)tx->send(data_frame(0x181, static_cast<uint8_t>(i)));
      (void)tx->send(data_frame(0x182, static_cast<uint8_t>(i)));
      received += rx->receive(buf, 0).count;
      if (i == 5000) (void)rx->inject_bus_off();
    }
    counts = counting.stop();
  }
  CHECK(received > 4000);
  CHECK(counts.allocations() == 0);
  CHECK(counts.mutex_locks == 0);
}
