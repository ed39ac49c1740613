/* A reader built against the header of ABI version 1 as it was before the time base
 * (fixtures/shm_abi1_main.h, a verbatim copy): it must keep reading a daemon that publishes the
 * time base. Plain C, so it is compiled as a client program would be. */
#include "old_reader.h"

#include "fixtures/shm_abi1_main.h"

int old_reader_read(const char* name, uint32_t axis, struct old_reader_result* out) {
  struct ds1928_shm_reader r;
  const int rc = ds1928_shm_reader_open(&r, name);
  if (rc != 0) return rc;
  struct ds1928_axis_data d;
  memset(&d, 0, sizeof d);
  const int read = ds1928_shm_read_axis(r.header, axis, &d);
  if (read == 0) {
    out->position_raw = d.position_raw;
    out->periods = d.periods;
    out->cycle = d.cycle;
    out->check_ok = ds1928_shm_check(&d) == d.check;
    out->validity = d.validity;
    out->last_cycle = ds1928_shm_last_cycle(r.header);
    out->alive = ds1928_shm_daemon_alive(r.header, ds1928_shm_now_ns(), 10);
    out->can_wait = r.wait != NULL;
  }
  ds1928_shm_reader_close(&r);
  return read;
}
