// Interposition of the allocation and mutex entry points. The real implementations are reached
// through glibc's exported __libc_* allocator entry points and the GLIBC_2.2.5 aliases of the
// mutex functions, so nothing here needs dlsym (which itself allocates and locks).
#include "support/alloc_counter.hpp"

#include <pthread.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <new>

extern "C" {
void* __libc_malloc(std::size_t size) noexcept;
void* __libc_calloc(std::size_t n, std::size_t size) noexcept;
void* __libc_realloc(void* p, std::size_t size) noexcept;
void* __libc_memalign(std::size_t alignment, std::size_t size) noexcept;
void* __libc_valloc(std::size_t size) noexcept;
void* __libc_pvalloc(std::size_t size) noexcept;
void __libc_free(void* p) noexcept;

int ds1928_real_pthread_mutex_lock(pthread_mutex_t* m) noexcept;
int ds1928_real_pthread_mutex_trylock(pthread_mutex_t* m) noexcept;
}
__asm__(".symver ds1928_real_pthread_mutex_lock,__pthread_mutex_lock@GLIBC_2.2.5");
__asm__(".symver ds1928_real_pthread_mutex_trylock,__pthread_mutex_trylock@GLIBC_2.2.5");

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define DS1928_SANITIZER_ALLOCATOR 1
#endif
// TSan intercepts pthread_mutex_lock itself; GCC 12's libasan interposes glibc's
// __pthread_mutex_lock, and its interceptor, reached from a program that defines
// pthread_mutex_lock, has no real function behind it (a call through address 0).
#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
#define DS1928_SANITIZER_MUTEXES 1
#endif

#ifdef DS1928_SANITIZER_ALLOCATOR
// The sanitizer's allocator owns malloc and operator new: replacing them collides with it. Its
// own hooks see every allocation and free of the process instead.
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*,
                                                                             std::size_t),
                                                         void (*free_hook)(const volatile void*));
#endif

namespace ds1928::test {
namespace {

struct ThreadState {
  bool on;
  HeapCounts counts;
};
// Trivially constructed, initial-exec TLS: reading it never calls into the allocator.
__attribute__((tls_model("initial-exec"))) thread_local ThreadState t_state{};

inline void note_alloc(uint64_t HeapCounts::*field, std::size_t size) noexcept {
  if (!t_state.on) return;
  if (t_state.counts.allocations() == 0) t_state.counts.first_size = size;
  ++(t_state.counts.*field);
}
inline void note_free(uint64_t HeapCounts::*field, const void* p) noexcept {
  if (p != nullptr && t_state.on) ++(t_state.counts.*field);
}

#ifndef DS1928_SANITIZER_ALLOCATOR
void* new_impl(std::size_t size, std::size_t alignment, bool nothrow) {
  note_alloc(&HeapCounts::new_calls, size);
  if (size == 0) size = 1;
  for (;;) {
    void* p = alignment > alignof(std::max_align_t) ? __libc_memalign(alignment, size)
                                                    : __libc_malloc(size);
    if (p != nullptr) return p;
    std::new_handler handler = std::get_new_handler();
    if (handler == nullptr) {
      if (nothrow) return nullptr;
      throw std::bad_alloc();
    }
    handler();
  }
}
void delete_impl(void* p) noexcept {
  note_free(&HeapCounts::delete_calls, p);
  __libc_free(p);
}
#else
// operator new and malloc reach the same hook: both count as malloc_calls (free_calls).
void sanitizer_malloc_hook(const volatile void*, std::size_t size) {
  note_alloc(&HeapCounts::malloc_calls, size);
}
void sanitizer_free_hook(const volatile void* p) {
  note_free(&HeapCounts::free_calls, const_cast<const void*>(p));
}
[[maybe_unused]] const int g_hooks_installed =
    __sanitizer_install_malloc_and_free_hooks(sanitizer_malloc_hook, sanitizer_free_hook);
#endif

}  // namespace

bool counts_new_separately() noexcept {
#ifdef DS1928_SANITIZER_ALLOCATOR
  return false;
#else
  return true;
#endif
}
bool counts_mutexes() noexcept {
#ifdef DS1928_SANITIZER_MUTEXES
  return false;
#else
  return true;
#endif
}

void begin_counting() noexcept {
  t_state.counts = HeapCounts{};
  t_state.on = true;
}
HeapCounts end_counting() noexcept {
  t_state.on = false;
  return t_state.counts;
}
HeapCounts current_counts() noexcept {
  return t_state.counts;
}
bool counting() noexcept {
  return t_state.on;
}

}  // namespace ds1928::test

using ds1928::test::HeapCounts;
using ds1928::test::note_alloc;
using ds1928::test::note_free;

#ifndef DS1928_SANITIZER_ALLOCATOR
using ds1928::test::delete_impl;
using ds1928::test::new_impl;

// ---- operator new / delete ----
void* operator new(std::size_t n) {
  return new_impl(n, 0, false);
}
void* operator new[](std::size_t n) {
  return new_impl(n, 0, false);
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return new_impl(n, 0, true);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return new_impl(n, 0, true);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t n, std::align_val_t a) {
  return new_impl(n, static_cast<std::size_t>(a), false);
}
void* operator new[](std::size_t n, std::align_val_t a) {
  return new_impl(n, static_cast<std::size_t>(a), false);
}
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  try {
    return new_impl(n, static_cast<std::size_t>(a), true);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  try {
    return new_impl(n, static_cast<std::size_t>(a), true);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p) noexcept {
  delete_impl(p);
}
void operator delete[](void* p) noexcept {
  delete_impl(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept {
  delete_impl(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept {
  delete_impl(p);
}
void operator delete(void* p, std::size_t) noexcept {
  delete_impl(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  delete_impl(p);
}
void operator delete(void* p, std::align_val_t) noexcept {
  delete_impl(p);
}
void operator delete[](void* p, std::align_val_t) noexcept {
  delete_impl(p);
}
void operator delete(void* p, std::size_t, std::align_val_t) noexcept {
  delete_impl(p);
}
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept {
  delete_impl(p);
}
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  delete_impl(p);
}
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  delete_impl(p);
}

// ---- malloc family ----
extern "C" {

void* malloc(std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, n * size);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  return __libc_realloc(p, size);
}
void* reallocarray(void* p, std::size_t n, std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, n * size);
  std::size_t bytes = 0;
  if (__builtin_mul_overflow(n, size, &bytes)) {
    errno = ENOMEM;
    return nullptr;
  }
  return __libc_realloc(p, bytes);
}
void free(void* p) noexcept {
  note_free(&HeapCounts::free_calls, p);
  __libc_free(p);
}
void* memalign(std::size_t alignment, std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  return __libc_memalign(alignment, size);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  if (alignment % sizeof(void*) != 0 || (alignment & (alignment - 1)) != 0) return EINVAL;
  void* p = __libc_memalign(alignment, size);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
void* valloc(std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  return __libc_valloc(size);
}
void* pvalloc(std::size_t size) noexcept {
  note_alloc(&HeapCounts::malloc_calls, size);
  return __libc_pvalloc(size);
}

}  // extern "C"
#endif  // DS1928_SANITIZER_ALLOCATOR

#ifndef DS1928_SANITIZER_MUTEXES
extern "C" {
// ---- mutexes ----
int pthread_mutex_lock(pthread_mutex_t* m) noexcept {
  if (ds1928::test::t_state.on) ++ds1928::test::t_state.counts.mutex_locks;
  return ds1928_real_pthread_mutex_lock(m);
}
int pthread_mutex_trylock(pthread_mutex_t* m) noexcept {
  if (ds1928::test::t_state.on) ++ds1928::test::t_state.counts.mutex_locks;
  return ds1928_real_pthread_mutex_trylock(m);
}

}  // extern "C"
#endif  // DS1928_SANITIZER_MUTEXES
