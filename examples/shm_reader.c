/* A control application's cycle in C: wait for every N-th publication of ds1928d, read one
 * axis consistently, print it. A daemon that stops (normally, or dies without a word) is
 * waited for: the reader maps the next one (a new generation) and carries on.
 *
 *   shm_reader [NAME [AXIS [EVERY [COUNT]]]]     defaults: /ds1928d 0 1 10 */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ds1928/shm.h"

static const char* validity_name(uint8_t v) {
  switch (v) {
    case DS1928_AXIS_VALID:
      return "valid";
    case DS1928_AXIS_STALE:
      return "stale";
    case DS1928_AXIS_BUS_DOWN:
      return "bus-down";
    case DS1928_AXIS_MODULE_ERROR:
      return "module-error";
    default:
      return "?";
  }
}

int main(int argc, char** argv) {
  const char* name = argc > 1 ? argv[1] : DS1928_SHM_DEFAULT_NAME;
  const uint32_t axis = argc > 2 ? (uint32_t)strtoul(argv[2], NULL, 0) : 0;
  const uint32_t every = argc > 3 ? (uint32_t)strtoul(argv[3], NULL, 0) : 1;
  const long count = argc > 4 ? strtol(argv[4], NULL, 0) : 10;

  struct ds1928_shm_reader reader;
  int rc = ds1928_shm_reader_open(&reader, name);
  if (rc != 0) {
    fprintf(stderr, "cannot map %s: %s\n", name, strerror(-rc));
    return 3;
  }
  printf("%s: generation %" PRIu64 ", %" PRIu32 " axes, cycle %" PRIu64 " ns\n", name,
         reader.generation, reader.header->axis_count, reader.header->cycle_period_ns);
  fflush(stdout);

  uint64_t seen = ds1928_shm_wait_start(reader.header);
  for (long n = 0; n < count;) {
    const int64_t deadline = ds1928_shm_now_ns() + 1000000000; /* 1 s */
    rc = ds1928_shm_wait(&reader, &seen, every, deadline);
    if (rc == DS1928_SHM_TIMEOUT || rc == DS1928_SHM_STOPPED) {
      if (rc == DS1928_SHM_TIMEOUT &&
          ds1928_shm_daemon_alive(reader.header, ds1928_shm_now_ns(), 10))
        continue;
      fprintf(stderr, "daemon %s; waiting for it to start again\n",
              rc == DS1928_SHM_STOPPED ? "stopped" : "not publishing");
      /* The stopped daemon removed its object, or its generation is still there: look again
       * every 200 ms until a new generation is mapped. */
      const struct timespec pause = {0, 200000000};
      while ((rc = ds1928_shm_reader_reopen(&reader, name)) == 0 || rc == -ENOENT)
        nanosleep(&pause, NULL);
      if (rc < 0) {
        fprintf(stderr, "cannot map %s: %s\n", name, strerror(-rc));
        ds1928_shm_reader_close(&reader);
        return 3;
      }
      printf("daemon restarted: generation %" PRIu64 "\n", reader.generation);
      fflush(stdout);
      seen = ds1928_shm_wait_start(reader.header);
      continue;
    }
    if (rc < 0) {
      fprintf(stderr, "wait: %s\n", strerror(-rc));
      ds1928_shm_reader_close(&reader);
      return 3;
    }
    struct ds1928_axis_data d;
    rc = ds1928_shm_read_axis(reader.header, axis, &d);
    if (rc != 0) {
      fprintf(stderr, "axis %" PRIu32 ": %s\n", axis, strerror(-rc));
      ds1928_shm_reader_close(&reader);
      return 1;
    }
    printf("cycle %" PRIu64 " axis %" PRIu32 " %s position %" PRId64
           " + %u/65536 periods (raw 0x%016" PRIx64 ") error_info 0x%02x\n",
           d.cycle, axis, validity_name(d.validity), d.periods, (unsigned)d.fraction,
           d.position_raw, (unsigned)d.error_info);
    ++n;
  }
  ds1928_shm_reader_close(&reader);
  return 0;
}
