/* An isochronous control loop in C: every EVERY-th bus cycle (the application cycle factor),
 * wake OFFSET_US after the daemon's publication with clock_nanosleep(TIMER_ABSTIME) on the
 * time base the daemon publishes (ds1928_shm_next_publication), read one axis and print its
 * age. No futex, no wake-up from the daemon: the loop is timed from the bus's own timeline, so
 * its phase against the bus is the same at every start.
 *
 *   isochronous_loop [NAME [AXIS [EVERY [OFFSET_US [COUNT]]]]]   defaults: /ds1928d 0 1 50 10
 *
 * Exit: 0 done, 3 cannot map, 4 the daemon publishes no time base (older daemon), 5 the
 * daemon stopped or went silent. */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ds1928/shm.h"

static void sleep_until(int64_t t_ns) {
  struct timespec ts;
  ts.tv_sec = (time_t)(t_ns / 1000000000);
  ts.tv_nsec = (long)(t_ns % 1000000000);
  /* Absolute: a signal or a late wake-up never shifts the later passes. */
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
  }
}

int main(int argc, char** argv) {
  const char* name = argc > 1 ? argv[1] : DS1928_SHM_DEFAULT_NAME;
  const uint32_t axis = argc > 2 ? (uint32_t)strtoul(argv[2], NULL, 0) : 0;
  const uint32_t every = argc > 3 ? (uint32_t)strtoul(argv[3], NULL, 0) : 1;
  const int64_t offset_ns = (argc > 4 ? strtoll(argv[4], NULL, 0) : 50) * 1000;
  const long count = argc > 5 ? strtol(argv[5], NULL, 0) : 10;

  struct ds1928_shm_reader reader;
  int rc = ds1928_shm_reader_open(&reader, name);
  if (rc != 0) {
    fprintf(stderr, "cannot map %s: %s\n", name, strerror(-rc));
    return 3;
  }
  const struct ds1928_shm_header* h = reader.header;
  if (!ds1928_shm_has_timebase(h)) {
    fprintf(stderr, "%s: the daemon publishes no time base (use ds1928_shm_wait)\n", name);
    ds1928_shm_reader_close(&reader);
    return 4;
  }
  printf("%s: cycle %" PRIu64 " ns, publication %" PRIu32 "/%" PRIu32
         " ns after the cycle start "
         "(p50/p99), every %" PRIu32 ", +%" PRId64 " us\n",
         name, h->cycle_period_ns, __atomic_load_n(&h->publish_offset_p50_ns, __ATOMIC_ACQUIRE),
         __atomic_load_n(&h->publish_offset_p99_ns, __ATOMIC_ACQUIRE), every, offset_ns / 1000);

  int64_t after = ds1928_shm_now_ns();
  const uint64_t step = every ? every : 1;
  uint64_t last = 0;
  int have_last = 0;
  for (long n = 0; n < count; ++n) {
    int64_t at = 0;
    uint64_t cycle = 0;
    rc = ds1928_shm_next_publication(h, after, every, &at, &cycle);
    if (rc == -EAGAIN) { /* no cycle yet: ask again in a moment */
      sleep_until(ds1928_shm_now_ns() + 10000000);
      --n;
      continue;
    }
    if (have_last && cycle <= last) { /* the measured offset grew: the same cycle again */
      at += (int64_t)(last + step - cycle) * (int64_t)h->cycle_period_ns;
      cycle = last + step;
    }
    last = cycle;
    have_last = 1;
    sleep_until(at + offset_ns);
    const int64_t woke = ds1928_shm_now_ns();
    if (!ds1928_shm_daemon_alive(h, woke, 10)) {
      fprintf(stderr, "%s: the daemon stopped or went silent\n", name);
      ds1928_shm_reader_close(&reader);
      return 5;
    }
    struct ds1928_axis_data d;
    if (ds1928_shm_read_axis(h, axis, &d) != 0) {
      fprintf(stderr, "axis %" PRIu32 ": no consistent record\n", axis);
      continue;
    }
    /* The application's work goes here: d is the record of `cycle` unless that publication
     * came later than its p99 (then d.cycle is older: count it, keep the rate). */
    printf("cycle %" PRIu64 " (timed %" PRIu64 "%s) periods %" PRId64 " age %" PRId64
           " us, woke +%" PRId64 " us after the publication\n",
           d.cycle, cycle, d.cycle == cycle ? "" : ", late", d.periods,
           d.pos_time_ns != 0 ? (woke - d.pos_time_ns) / 1000 : -1, (woke - at) / 1000);
    /* A pass late by a whole step resumes at the next publication ahead (no burst). */
    after = woke - at < (int64_t)h->cycle_period_ns * (int64_t)(every ? every : 1) ? at : woke;
  }
  ds1928_shm_reader_close(&reader);
  return 0;
}
