/* The shared-memory readers of the sync bench (run_sync_bench.sh), at an application cycle of
 * EVERY bus cycles:
 *   wait  sleeps on the futex for every EVERY-th publication (ds1928_shm_wait), then reads;
 *   iso   sleeps with clock_nanosleep(TIMER_ABSTIME) until the published time base's next
 *         EVERY-th publication plus OFFSET_US (ds1928_shm_next_publication), then reads.
 * At each read: age = now - pos_time_ns of axis 0. Runs SECONDS, then prints one line (ns):
 *   <mode> <reads> <p1> <p50> <p99> <max> <reads of the timed cycle (iso) or 0>
 *
 *   reader_age SHM_NAME wait|iso EVERY OFFSET_US SECONDS */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ds1928/shm.h"

static int by_value(const void* a, const void* b) {
  const int64_t x = *(const int64_t*)a, y = *(const int64_t*)b;
  return x < y ? -1 : x > y;
}

static int64_t pick(const int64_t* sorted, size_t n, double q) {
  size_t i = (size_t)(q * (double)n);
  return sorted[i < n ? i : n - 1];
}

static void sleep_until(int64_t t) {
  struct timespec ts = {(time_t)(t / 1000000000), (long)(t % 1000000000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
  }
}

int main(int argc, char** argv) {
  if (argc != 6) {
    fprintf(stderr, "usage: reader_age SHM_NAME wait|iso EVERY OFFSET_US SECONDS\n");
    return 2;
  }
  const int iso = strcmp(argv[2], "iso") == 0;
  const uint32_t every = (uint32_t)strtoul(argv[3], NULL, 10);
  const int64_t offset = strtoll(argv[4], NULL, 10) * 1000;
  const int64_t seconds = strtoll(argv[5], NULL, 10);
  struct ds1928_shm_reader r;
  int rc = ds1928_shm_reader_open(&r, argv[1]);
  if (rc != 0 || (!iso && !r.wait) || (iso && !ds1928_shm_has_timebase(r.header))) {
    fprintf(stderr, "reader_age: %s: cannot map (%d), wait or find a time base\n", argv[1], rc);
    return 1;
  }
  const size_t cap = (size_t)(seconds * 1000000000 / (int64_t)r.header->cycle_period_ns) + 16;
  int64_t* age = calloc(cap, sizeof *age);
  if (!age) return 1;
  const int64_t end = ds1928_shm_now_ns() + seconds * 1000000000;
  uint64_t seen = ds1928_shm_wait_start(r.header);
  int64_t after = ds1928_shm_now_ns();
  size_t n = 0, timed = 0;
  uint64_t last = 0;
  int have_last = 0;
  while (n < cap && ds1928_shm_now_ns() < end) {
    uint64_t cycle = 0;
    if (iso) {
      int64_t at = 0;
      if (ds1928_shm_next_publication(r.header, after, every, &at, &cycle) != 0) return 1;
      if (have_last && cycle <= last) { /* the measured offset grew: the same cycle again */
        at += (int64_t)(last + every - cycle) * (int64_t)r.header->cycle_period_ns;
        cycle = last + every;
      }
      last = cycle;
      have_last = 1;
      sleep_until(at + offset);
      after = at;
    } else {
      rc = ds1928_shm_wait(&r, &seen, every, ds1928_shm_now_ns() + 1000000000);
      if (rc != 0) {
        fprintf(stderr, "reader_age: wait returned %d\n", rc);
        return 1;
      }
    }
    struct ds1928_axis_data d;
    if (ds1928_shm_read_axis(r.header, 0, &d) != 0 || d.validity != DS1928_AXIS_VALID) continue;
    age[n++] = ds1928_shm_now_ns() - d.pos_time_ns;
    timed += iso && d.cycle == cycle;
  }
  if (n == 0) return 1;
  qsort(age, n, sizeof *age, by_value);
  printf("%s %zu %lld %lld %lld %lld %zu\n", argv[2], n, (long long)pick(age, n, 0.01),
         (long long)pick(age, n, 0.5), (long long)pick(age, n, 0.99), (long long)age[n - 1], timed);
  ds1928_shm_reader_close(&r);
  free(age);
  return 0;
}
