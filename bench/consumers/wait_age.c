/* The waiting reader of the timing bench (run_age_bench.sh): sleeps on the futex for every
 * publication (ds1928_shm_wait), reads axis 0 and records, at that read, the age of the position
 * (now - pos_time_ns) and of the publication (now - publish_ns). Prints one line:
 *   waiting <n> <age p50> <age p99> <age max> <pub p50> <pub p99> <pub max>   (ns)
 *
 *   wait_age SHM_NAME COUNT */
#include <stdio.h>
#include <stdlib.h>

#include "ds1928/shm.h"

static int by_value(const void* a, const void* b) {
  const int64_t x = *(const int64_t*)a, y = *(const int64_t*)b;
  return x < y ? -1 : x > y;
}

static int64_t pick(const int64_t* sorted, size_t n, double q) {
  size_t i = (size_t)(q * (double)n);
  return sorted[i < n ? i : n - 1];
}

int main(int argc, char** argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: wait_age SHM_NAME COUNT\n");
    return 2;
  }
  const size_t count = (size_t)strtoul(argv[2], NULL, 10);
  int64_t* age = calloc(count, sizeof *age);
  int64_t* pub = calloc(count, sizeof *pub);
  struct ds1928_shm_reader r;
  int rc = ds1928_shm_reader_open(&r, argv[1]);
  if (rc != 0 || !age || !pub || !r.wait) {
    fprintf(stderr, "wait_age: %s: cannot map (%d) or wait\n", argv[1], rc);
    return 1;
  }
  uint64_t seen = ds1928_shm_wait_start(r.header);
  size_t n = 0;
  while (n < count) {
    rc = ds1928_shm_wait(&r, &seen, 1, ds1928_shm_now_ns() + 1000000000);
    if (rc != 0) {
      fprintf(stderr, "wait_age: wait returned %d\n", rc);
      return 1;
    }
    struct ds1928_axis_data d;
    if (ds1928_shm_read_axis(r.header, 0, &d) != 0 || d.validity != DS1928_AXIS_VALID) continue;
    const int64_t now = ds1928_shm_now_ns();
    age[n] = now - d.pos_time_ns;
    pub[n] = now - d.publish_ns;
    ++n;
  }
  qsort(age, n, sizeof *age, by_value);
  qsort(pub, n, sizeof *pub, by_value);
  printf("waiting %zu %lld %lld %lld %lld %lld %lld\n", n, (long long)pick(age, n, 0.5),
         (long long)pick(age, n, 0.99), (long long)age[n - 1], (long long)pick(pub, n, 0.5),
         (long long)pick(pub, n, 0.99), (long long)pub[n - 1]);
  ds1928_shm_reader_close(&r);
  free(age);
  free(pub);
  return 0;
}
