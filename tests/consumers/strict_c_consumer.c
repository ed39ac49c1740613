/* A consumer of include/ds1928/shm.h in strict ISO C, without any feature-test macro. Built
 * twice by header_strict_c_test.sh: with the header first, and with -DSYSTEM_HEADER_FIRST after
 * <stdio.h> (glibc then declares ISO C only). Uses every function of the header so that each is
 * compiled, and prints the result of opening the name given (the test passes one that does not
 * exist) and whether CLOCK_MONOTONIC reads. */
/* The order of the includes is what this file tests. */
/* clang-format off */
#ifdef SYSTEM_HEADER_FIRST
#include <stdio.h>
#endif
#include "ds1928/shm.h"
#include <stdio.h>
/* clang-format on */

int main(int argc, char** argv) {
  const char* name = argc > 1 ? argv[1] : DS1928_SHM_DEFAULT_NAME;
  struct ds1928_shm_reader r;
  int rc = ds1928_shm_reader_open(&r, name);
  if (rc == 0) {
    struct ds1928_axis_data d;
    uint64_t seen = ds1928_shm_wait_start(r.header);
    (void)ds1928_shm_wait(&r, &seen, 1, ds1928_shm_now_ns() + 10000000);
    if (ds1928_shm_read_axis(r.header, 0, &d) == 0 && ds1928_shm_check(&d) == d.check)
      printf("axis 0 cycle %llu alive %d\n", (unsigned long long)d.cycle,
             ds1928_shm_daemon_alive(r.header, ds1928_shm_now_ns(), 10));
    (void)ds1928_shm_reader_reopen(&r, name);
    ds1928_shm_reader_close(&r);
  }
  const int64_t t1 = ds1928_shm_now_ns(), t2 = ds1928_shm_now_ns();
  /* The time base on a header built here: cycle n starts at 1 s + n ms, publication 40 µs in;
   * the next publication after 1.0051 s of a multiple of 4 is cycle 8's, at 1.008040 s. */
  struct ds1928_shm_header h;
  memset(&h, 0, sizeof h);
  int64_t at = 0;
  uint64_t cycle = 0;
  const int none = ds1928_shm_next_publication(&h, 0, 1, &at, &cycle);
  h.features = DS1928_SHM_FEATURE_TIMEBASE;
  h.cycle_period_ns = 1000000;
  h.timebase_t0_ns = 1000000000;
  h.publish_offset_p99_ns = 40000;
  const int tb = ds1928_shm_next_publication(&h, 1005100000, 4, &at, &cycle);
  printf("open %s: %d, clock %s, timebase %s\n", name, rc, t1 > 0 && t2 >= t1 ? "ok" : "broken",
         none == -ENOTSUP && tb == 0 && cycle == 8 && at == 1008040000 ? "ok" : "broken");
  return 0;
}
