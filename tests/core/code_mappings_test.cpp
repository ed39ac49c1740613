// The walk over the process' code mappings that start-up (dropping the libraries' start-up code)
// and the allocation proofs (locking all code before their window) share.
#include <sys/mman.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "core/rt_setup.hpp"

namespace {

struct Mapping {
  uintptr_t lo, hi;
  std::string path;
};

// The mappings one of rt_setup's walks visits.
std::vector<Mapping> collect(void (*walk)(ds1928::rt::CodeMappingVisitor, void*) noexcept) {
  std::vector<Mapping> out;
  walk(
      [](uintptr_t lo, uintptr_t hi, const char* path, void* context) {
        static_cast<std::vector<Mapping>*>(context)->push_back({lo, hi, path});
      },
      &out);
  return out;
}
std::vector<Mapping> code_mappings() {
  return collect(&ds1928::rt::for_each_code_mapping);
}
std::vector<Mapping> unwritten_mappings() {
  return collect(&ds1928::rt::for_each_unwritten_mapping);
}

// VmLck of /proc/self/status: bytes of this process' memory locked in RAM.
std::size_t locked_bytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmLck:", 0) == 0) return std::stoul(line.substr(6)) * 1024;
  FAIL("no VmLck in /proc/self/status");
  return 0;
}

}  // namespace

TEST_CASE("the code mappings are the executable's and its libraries', this function among them",
          "[core][rt]") {
  const auto maps = code_mappings();
  char exe[4096] = {};
  REQUIRE(readlink("/proc/self/exe", exe, sizeof(exe) - 1) > 0);
  const auto here = reinterpret_cast<uintptr_t>(&code_mappings);
  bool exe_seen = false;
  bool here_seen = false;
  for (const Mapping& m : maps) {
    CHECK(m.lo < m.hi);
    CHECK(m.path.front() == '/');  // files only: no [vdso], no anonymous mapping
    exe_seen = exe_seen || m.path == exe;
    here_seen = here_seen || (m.lo <= here && here < m.hi);
  }
  CHECK(exe_seen);
  CHECK(here_seen);
  CHECK(maps.size() >= 2);  // the executable and at least libc
}

TEST_CASE("lock_code_mappings locks every page of code", "[core][rt]") {
  // mlock needs CAP_IPC_LOCK or room under RLIMIT_MEMLOCK: as root (CI) it has both.
  if (geteuid() != 0) {
    SUCCEED("not root: mlock may be refused");
    return;
  }
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // Every sanitizer runtime intercepts mlock and locks nothing (docs/testing.md): the lock is
  // proven in the normal build.
  WARN("sanitizer build: mlock is intercepted, the lock is not judged");
  return;
#endif
  std::size_t code = 0, unwritten = 0;
  for (const Mapping& m : code_mappings()) code += m.hi - m.lo;
  for (const Mapping& m : unwritten_mappings()) unwritten += m.hi - m.lo;
  // The read-only data is more than the code alone: libm's constant tables among it (sin()
  // reads one page of __sincostab only for some arguments — the fault an allocation proof once
  // counted on the cycle thread under memory load).
  CHECK(unwritten > code);
  const std::size_t before = locked_bytes();
  ds1928::rt::lock_code_mappings();
  CHECK(locked_bytes() >= before + unwritten);
  for (const Mapping& m : unwritten_mappings())
    (void)munlock(reinterpret_cast<void*>(m.lo), m.hi - m.lo);
}

TEST_CASE("the unwritten mappings are the code mappings and the files' read-only data",
          "[core][rt]") {
  const auto code = code_mappings();
  const auto all = unwritten_mappings();
  for (const Mapping& c : code) {
    bool found = false;
    for (const Mapping& m : all) found = found || (m.lo == c.lo && m.hi == c.hi);
    CHECK(found);
  }
  // libm (linked by every test binary) has a read-only data mapping besides its code.
  bool libm_rodata = false;
  for (const Mapping& m : all) {
    bool is_code = false;
    for (const Mapping& c : code) is_code = is_code || (m.lo == c.lo && m.hi == c.hi);
    libm_rodata = libm_rodata || (!is_code && m.path.find("libm.so") != std::string::npos);
  }
  CHECK(libm_rodata);
}
