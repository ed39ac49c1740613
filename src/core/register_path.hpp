// The one way an acyclic register request (configuration, identification, EnDatAck) travels
// between the daemon's normal thread and a bus: RegisterPath queues the requests and the results
// in fixed storage (SPSC, no allocation, no lock), and hands each request on the cycle thread to
// the bus through RegisterTarget, the one small interface every bus implements (POWERLINK: an SDO
// transfer of the MN; CAN-I/O: an expedited SDO job; simulator: the module's register).
//
// Rules every bus follows through it: requests are offered in submission order; a request the bus
// cannot take yet stays queued (kWait) ahead of the later ones; every request taken gets exactly
// one result through complete(); while a result waits for room (nobody polls) nothing more is
// offered, so no result is ever dropped.
#pragma once

#include <cstddef>
#include <cstdint>
#include <system_error>

#include "core/spsc_queue.hpp"

namespace ds1928 {

// One register access, as the services ask for it and every bus serves it.
struct RegisterRequest {
  uint32_t tag = 0;  // caller's correlation id
  uint16_t axis = 0;
  uint16_t reg = 0;  // datasheet register number (module_image.hpp, namespace reg)
  uint8_t size = 1;  // 1, 2 or 4 bytes
  bool write = false;
  uint32_t value = 0;  // for writes
};
struct RegisterResult {
  uint32_t tag = 0;
  std::error_code error;  // empty on success
  uint32_t value = 0;     // for reads
};

// Requests (and results) a bus holds: submitted and not yet taken (not yet polled).
inline constexpr std::size_t kRegisterQueueDepth = 64;

enum class RegisterPathError {
  kQueueFull = 1,  // kRegisterQueueDepth requests wait already: submit again later
};
[[nodiscard]] const std::error_category& register_path_category() noexcept;
[[nodiscard]] inline std::error_code make_error_code(RegisterPathError e) noexcept {
  return {static_cast<int>(e), register_path_category()};
}

// What a bus implements to serve register requests (cycle thread).
class RegisterTarget {
 public:
  enum class Offer : uint8_t {
    kTaken,  // the bus owns the request now: it completes it, at once or in a later cycle
    kWait,   // not now (its queue is full, its node is being configured): offered again later
  };
  [[nodiscard]] virtual Offer offer(const RegisterRequest& request) noexcept = 0;

 protected:
  ~RegisterTarget() = default;
};

class RegisterPath {
 public:
  // ---- Normal thread (the single producer of requests, the single consumer of results).
  // Empty, or RegisterPathError::kQueueFull (nothing queued; the caller submits again later).
  [[nodiscard]] std::error_code submit(const RegisterRequest& request) noexcept {
    return requests_.try_push(request) ? std::error_code{}
                                       : make_error_code(RegisterPathError::kQueueFull);
  }
  // True and `out` filled when a result is ready.
  [[nodiscard]] bool poll(RegisterResult& out) noexcept {
    auto r = results_.try_pop();
    if (!r) return false;
    out = *r;
    return true;
  }

  // ---- Cycle thread.
  // Offers the queued requests in order until the target waits, takes `max` of them, or a result
  // waits for room. Returns how many the target took.
  std::size_t serve(RegisterTarget& target, std::size_t max = kRegisterQueueDepth) noexcept {
    std::size_t taken = 0;
    while (taken < max && flush()) {
      const RegisterRequest* r = requests_.front();
      if (r == nullptr) break;
      const RegisterRequest request = *r;
      if (target.offer(request) == RegisterTarget::Offer::kWait) break;
      requests_.drop_front();
      ++taken;
    }
    return taken;
  }
  // The one result of a taken request. When the result queue is full it is held (and nothing is
  // offered) until the normal thread polls; false then. Call only while can_complete().
  bool complete(const RegisterResult& result) noexcept {
    if (held_) return false;  // a caller bug: at most one result waits
    if (results_.try_push(result)) return true;
    held_result_ = result;
    held_ = true;
    return false;
  }
  // True when no result waits for room (after trying to hand the waiting one over).
  [[nodiscard]] bool flush() noexcept {
    if (held_ && results_.try_push(held_result_)) held_ = false;
    return !held_;
  }
  [[nodiscard]] bool can_complete() const noexcept { return !held_; }
  [[nodiscard]] bool requests_empty() const noexcept { return requests_.empty(); }

 private:
  SpscQueue<RegisterRequest, kRegisterQueueDepth> requests_;  // normal → cycle thread
  SpscQueue<RegisterResult, kRegisterQueueDepth> results_;    // cycle → normal thread
  RegisterResult held_result_{};                              // cycle thread
  bool held_ = false;
};

}  // namespace ds1928

namespace std {
template <>
struct is_error_code_enum<ds1928::RegisterPathError> : true_type {};
}  // namespace std
