/* The old reader's result, in types both the C and the C++ side declare alike. */
#pragma once
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

struct old_reader_result {
  uint64_t position_raw;
  int64_t periods;
  uint64_t cycle;
  uint64_t last_cycle;
  int check_ok;
  int validity;
  int alive;
  int can_wait;
};

/* 0, or what ds1928_shm_reader_open/ds1928_shm_read_axis of the old header returned. */
int old_reader_read(const char* name, uint32_t axis, struct old_reader_result* out);

#ifdef __cplusplus
}
#endif
