/* ds1928d shared memory: layout and a header-only reader, usable from C11 and C++.
 *
 * The daemon publishes one record per axis every cycle into the POSIX shared memory object
 * <name> (default "/ds1928d", i.e. /dev/shm/ds1928d) and signals each publication through a
 * second, small object <name>.wait that readers may write (they register there while they
 * sleep). The protocol is described in docs/shared-memory.md; in short:
 *
 *  - Every field that changes after start-up is accessed atomically (the functions below use
 *    the GCC/Clang __atomic builtins, available in C and C++). Fields are plain integers so
 *    that any language can map the layout.
 *  - A record is a seqlock: `seq` is odd while the daemon writes it. A reader copies the data
 *    between two equal, even loads of `seq`. The daemon never waits for a reader.
 *  - `check` is a hash of the other data words: a reader that skipped the seqlock protocol (or
 *    a test) can tell a torn copy from a consistent one.
 *  - A new `generation` at every daemon start tells a restarted daemon from the old one; the
 *    publication time that stops advancing tells a dead one.
 *  - Waiting for the next publication is a futex on `ds1928_shm_wait_area.futex`; a reader
 *    registers in a "factor slot" so that it is woken only on the cycles it asked for, and the
 *    daemon makes the wake-up system call only when someone is registered.
 *  - Or, without the daemon's help, on the bus's own timeline: the header's time base
 *    (`features` bit DS1928_SHM_FEATURE_TIMEBASE: t0, period, measured publication offset) gives
 *    the next publication's instant (ds1928_shm_next_publication) to sleep until with
 *    clock_nanosleep(TIMER_ABSTIME), every N-th cycle.
 *
 * Requires Linux and GCC or Clang; C99, C11, C17 (also strict ISO modes such as -std=c99
 * -pedantic) and C++. The functions below need POSIX and syscall(): when the translation unit
 * chose no feature-test macro, this header selects _DEFAULT_SOURCE (glibc's default outside
 * strict ISO mode); when a system header came first in strict ISO mode, it declares the few
 * functions it needs itself. No feature-test macro is needed from the user, in any order. */
#ifndef DS1928_SHM_H
#define DS1928_SHM_H

#if !defined(__cplusplus) && !defined(_GNU_SOURCE) && !defined(_DEFAULT_SOURCE) &&   \
    !defined(_POSIX_C_SOURCE) && !defined(_XOPEN_SOURCE) && !defined(_BSD_SOURCE) && \
    !defined(_SVID_SOURCE) && !defined(_POSIX_SOURCE)
#define _DEFAULT_SOURCE 1
#endif

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <linux/futex.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

/* A system header came first in a strict ISO C translation unit (or the user chose a narrower
 * feature-test macro): glibc then declared only what that mode allows, and the _DEFAULT_SOURCE
 * above came too late. The few POSIX/Linux names used below are declared here, with glibc's own
 * types (compatible with its declarations). */
#if defined(__GLIBC__) && !defined(__cplusplus)
#if !defined(__USE_POSIX199309)
#ifndef _STRUCT_TIMESPEC /* C99: ISO C declares no struct timespec before C11 */
#define _STRUCT_TIMESPEC 1
struct timespec {
  __time_t tv_sec;
  __syscall_slong_t tv_nsec;
};
#endif
#ifndef CLOCK_MONOTONIC
#define CLOCK_MONOTONIC 1 /* Linux ABI */
#endif
extern int clock_gettime(__clockid_t clock_id, struct timespec* tp);
#endif
#if !defined(__USE_MISC)
extern long int syscall(long int sysno, ...);
#endif
#endif
#if !defined(O_CLOEXEC) && defined(__O_CLOEXEC)
#define O_CLOEXEC __O_CLOEXEC
#endif
#ifdef NAME_MAX
#define DS1928_SHM_NAME_MAX NAME_MAX
#else
#define DS1928_SHM_NAME_MAX 255 /* Linux; <limits.h> names it only outside strict ISO C */
#endif

#ifdef __cplusplus
extern "C" {
#endif

#define DS1928_SHM_MAGIC UINT64_C(0x4d48533832393144)      /* "D1928SHM" in memory order */
#define DS1928_SHM_WAIT_MAGIC UINT64_C(0x5449415738323944) /* "D928WAIT" in memory order */
#define DS1928_SHM_ABI_VERSION 1u
#define DS1928_SHM_DEFAULT_NAME "/ds1928d"
#define DS1928_SHM_WAIT_SUFFIX ".wait"
#define DS1928_SHM_WAIT_SLOTS 16u

/* Daemon state in the header. */
enum ds1928_daemon_state {
  DS1928_DAEMON_STARTING = 0, /* object created, no cycle published yet */
  DS1928_DAEMON_RUNNING = 1,  /* cycling */
  DS1928_DAEMON_STOPPING = 2, /* shutting down, publications may stop at any time */
  DS1928_DAEMON_STOPPED = 3   /* exited cleanly; this object is no longer updated */
};

/* Validity of one axis record. */
enum ds1928_axis_validity {
  DS1928_AXIS_VALID = 0,       /* fresh inputs this cycle, no module error */
  DS1928_AXIS_STALE = 1,       /* no fresh inputs this cycle: the data is the last good one */
  DS1928_AXIS_BUS_DOWN = 2,    /* the bus is not cycling */
  DS1928_AXIS_MODULE_ERROR = 3 /* an error bit that invalidates the position is set (a fault) */
};

/* Time source of pos_time_ns (core/bus.hpp TimeSource). */
enum ds1928_time_source {
  DS1928_TIME_NONE = 0,
  DS1928_TIME_NETTIME = 1,     /* module's PosTime (NetTime), mapped to CLOCK_MONOTONIC */
  DS1928_TIME_RX_TIMESTAMP = 2 /* master's reception time of the inputs */
};

/* ds1928_shm_header.features: what this daemon publishes beyond the ABI version 1 base (a bit
 * set; 0 in daemons that predate it). Bits not named here are reserved. */
#define DS1928_SHM_FEATURE_TIMEBASE 0x01u /* the time base fields (docs/shared-memory.md) */
/* The additional-information channels (struct ds1928_axis_info in each record, their names in
 * the table at info_names_offset; docs/shared-memory.md). */
#define DS1928_SHM_FEATURE_INFO 0x02u

/* Additional-information channels per axis (EnDatInfo01..04, datasheet 11.8.3) and the room for
 * one channel's name (NUL-terminated) in the names table. */
#define DS1928_INFO_CHANNELS 4u
#define DS1928_INFO_NAME_LEN 32u
/* ds1928_axis_info.age_us of a channel that never had a valid value. */
#define DS1928_INFO_AGE_NEVER UINT32_MAX

/* ds1928_shm_header.timebase_kind: the clock the cycle starts are aligned to. */
enum ds1928_timebase_kind {
  DS1928_TIMEBASE_MONOTONIC = 0, /* t0 chosen at the daemon's start */
  DS1928_TIMEBASE_TAI = 1        /* cycle starts on multiples of the period in CLOCK_TAI */
};

/* ds1928_axis_data.flags */
#define DS1928_AXIS_NEW_POSITION 0x01u   /* PosCycle changed: a new EnDat position this cycle */
#define DS1928_AXIS_FRACTION_VALID 0x02u /* the fraction's low 3 bits are zero */
#define DS1928_AXIS_FRESH 0x04u          /* inputs arrived this cycle */
/* A fault-class bit of error_info / endat_error is set (docs/registers.md, error bits). */
#define DS1928_AXIS_FAULT 0x08u
/* A warning-class bit of error_info / endat_warning is set; the position stays valid. */
#define DS1928_AXIS_WARNING 0x10u
/* An analogue error holds the last good position (datasheet 11.7.6): validity stale. */
#define DS1928_AXIS_HELD 0x20u

/* Payload of one axis record: what a reader gets. 9 words of 64 bits. */
struct ds1928_axis_data {
  uint64_t position_raw;  /* PositionHW:PositionLW, 64-bit sin/cos fixed point */
  int64_t periods;        /* whole sine periods (bits 63..16, sign-extended if signed format) */
  int64_t pos_time_ns;    /* acquisition instant, CLOCK_MONOTONIC ns (0 if none) */
  int64_t publish_ns;     /* CLOCK_MONOTONIC ns when the daemon published this record */
  uint64_t cycle;         /* daemon cycle index of the publication */
  int32_t position_sdc;   /* low 32 bits read signed ("SDC" view) */
  uint32_t pos_time_raw;  /* PosTime as sent (NetTime µs, 32 bit) */
  uint32_t endat_error;   /* EnDatError word (docs/registers.md) as last read by the daemon */
  uint32_t endat_warning; /* EnDatWarning word (docs/registers.md) as last read by the daemon */
  uint16_t fraction;      /* fraction of one period (bits 15..0) */
  uint8_t time_source;    /* enum ds1928_time_source */
  int8_t pos_cycle;       /* PosCycle */
  uint8_t error_info;     /* ErrorInfo bits */
  uint8_t validity;       /* enum ds1928_axis_validity */
  uint8_t flags;          /* DS1928_AXIS_* flags */
  uint8_t reserved;
  uint64_t check; /* ds1928_shm_check() of the 8 words above */
};

#define DS1928_AXIS_DATA_WORDS 9u

/* The additional-information channels of one axis (DS1928_SHM_FEATURE_INFO): 5 words of 64 bits,
 * written under the record's seqlock with the payload (ds1928_shm_read_axis_info). Channel n
 * (0-based) is EnDatInfo0(n+1); its name is ds1928_shm_info_name(). */
struct ds1928_axis_info {
  int32_t value[DS1928_INFO_CHANNELS]; /* EnDatInfo0N as last read valid (INT channels signed) */
  uint32_t
      age_us[DS1928_INFO_CHANNELS]; /* since that read (saturating), or DS1928_INFO_AGE_NEVER */
  uint8_t valid;      /* bit n: EnDatInfoOK bit n in the last read, the channel configured */
  uint8_t configured; /* bit n: channel n is configured (axes[].info) */
  uint8_t reserved[6];
};

#define DS1928_AXIS_INFO_WORDS 5u

/* One axis record: a seqlock around the payload, two cache lines. */
struct ds1928_shm_axis {
  uint64_t seq; /* atomic; odd while the daemon writes */
  union {
    struct ds1928_axis_data data;
    uint64_t words[DS1928_AXIS_DATA_WORDS]; /* accessed word by word, atomically */
  } u;
  /* Time base (DS1928_SHM_FEATURE_TIMEBASE), atomic, outside the seqlock: from the acquisition
   * instant (pos_time_ns) to the publication, this cycle's (0 when no fresh stamped input) and
   * the largest of the last measurement window: the axis' T_IO_Input equivalent. */
  uint32_t acq_to_publish_ns;
  uint32_t acq_to_publish_max_ns;
  /* Additional information (DS1928_SHM_FEATURE_INFO; zero in daemons without it), inside the
   * seqlock: written word by word, atomically, between the two stores of `seq`. */
  union {
    struct ds1928_axis_info info;
    uint64_t words[DS1928_AXIS_INFO_WORDS];
  } x;
};

/* The object starts with this header; the records follow at offset header_size. */
struct ds1928_shm_header {
  /* Constant after creation. */
  uint64_t magic;           /* DS1928_SHM_MAGIC, stored last (release) at creation */
  uint32_t abi_version;     /* DS1928_SHM_ABI_VERSION */
  uint32_t header_size;     /* sizeof(struct ds1928_shm_header) */
  uint32_t record_size;     /* sizeof(struct ds1928_shm_axis) */
  uint32_t axis_count;      /* records that follow */
  uint64_t generation;      /* new at every daemon start (CLOCK_REALTIME ns of the start) */
  uint64_t cycle_period_ns; /* the daemon's cycle period */
  int32_t daemon_pid;       /* for messages */
  uint32_t features;        /* DS1928_SHM_FEATURE_* bits (0 in older daemons) */
  /* Time base (DS1928_SHM_FEATURE_TIMEBASE), atomic: cycle n starts at timebase_t0_ns +
   * n * cycle_period_ns on CLOCK_MONOTONIC (0 = no cycle yet); it moves only when a clock step
   * re-anchors the timeline. */
  int64_t timebase_t0_ns;
  int64_t timebase_tai_offset_ns; /* CLOCK_TAI - CLOCK_MONOTONIC of the timeline (tai only) */
  /* Second cache line: changes at run time (all atomic). */
  uint32_t daemon_state;          /* enum ds1928_daemon_state */
  uint32_t timebase_steps;        /* re-anchors after a step of the aligned clock */
  uint64_t last_cycle;            /* cycle index of the last publication */
  int64_t last_publish_ns;        /* CLOCK_MONOTONIC ns of the last publication (0 = none yet) */
  uint64_t publish_count;         /* publications since start */
  uint32_t publish_offset_p50_ns; /* publication - cycle start, last measurement window */
  uint32_t publish_offset_p99_ns; /*   (0 = not measured yet) */
  uint32_t publish_offset_max_ns;
  uint32_t timebase_kind;        /* enum ds1928_timebase_kind */
  int64_t timebase_last_step_ns; /* how far the last re-anchor moved the cycle starts */
  /* DS1928_SHM_FEATURE_INFO, constant after creation: offset from the object's start of the
   * channel names, axis_count * DS1928_INFO_CHANNELS entries of DS1928_INFO_NAME_LEN bytes
   * (axis-major; an empty name: the channel is off). 0 in daemons without the feature. */
  uint32_t info_names_offset;
  uint32_t reserved3;
};

/* <name>.wait: written by readers (registration) and by the daemon (futex word). */
struct ds1928_shm_wait_slot {
  uint32_t factor;  /* 0 = free; else woken on publications whose cycle index is a multiple */
  uint32_t waiters; /* readers asleep (or about to sleep) in this slot */
};
struct ds1928_shm_wait_area {
  uint64_t magic;      /* DS1928_SHM_WAIT_MAGIC, stored last at creation */
  uint64_t generation; /* same as the data object's header */
  uint64_t reserved0[6];
  uint32_t futex; /* changes (+1) at every publication and when the daemon stops */
  uint32_t reserved1[15];
  struct ds1928_shm_wait_slot slots[DS1928_SHM_WAIT_SLOTS]; /* bit i of the futex bitset = slot i */
};

#if defined(__cplusplus)
static_assert(sizeof(struct ds1928_axis_data) == 8 * DS1928_AXIS_DATA_WORDS, "axis data layout");
static_assert(sizeof(struct ds1928_axis_info) == 8 * DS1928_AXIS_INFO_WORDS, "axis info layout");
static_assert(sizeof(struct ds1928_shm_axis) == 128, "axis record layout");
static_assert(sizeof(struct ds1928_shm_header) == 128, "header layout");
static_assert(sizeof(struct ds1928_shm_wait_area) == 256, "wait area layout");
#elif defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L
_Static_assert(sizeof(struct ds1928_axis_data) == 8 * DS1928_AXIS_DATA_WORDS, "axis data layout");
_Static_assert(sizeof(struct ds1928_axis_info) == 8 * DS1928_AXIS_INFO_WORDS, "axis info layout");
_Static_assert(sizeof(struct ds1928_shm_axis) == 128, "axis record layout");
_Static_assert(sizeof(struct ds1928_shm_header) == 128, "header layout");
_Static_assert(sizeof(struct ds1928_shm_wait_area) == 256, "wait area layout");
#else /* C99: a negative array size stops the compilation instead */
typedef char
    ds1928_shm_layout_check[(sizeof(struct ds1928_axis_data) == 8 * DS1928_AXIS_DATA_WORDS) &&
                                    sizeof(struct ds1928_axis_info) == 8 * DS1928_AXIS_INFO_WORDS &&
                                    sizeof(struct ds1928_shm_axis) == 128 &&
                                    sizeof(struct ds1928_shm_header) == 128 &&
                                    sizeof(struct ds1928_shm_wait_area) == 256
                                ? 1
                                : -1];
#endif

/* Results of the functions below besides 0 and -errno. */
#define DS1928_SHM_TIMEOUT 1 /* ds1928_shm_wait: deadline passed */
#define DS1928_SHM_STOPPED 2 /* ds1928_shm_wait: the daemon stopped (object no longer updated) */

/* Check value over the first 8 payload words: a torn copy fails it with near certainty. */
static inline uint64_t ds1928_shm_check(const struct ds1928_axis_data* d) {
  const uint64_t* w = (const uint64_t*)(const void*)d;
  uint64_t h = UINT64_C(0x6a09e667f3bcc909);
  for (unsigned i = 0; i + 1 < DS1928_AXIS_DATA_WORDS; ++i) {
    h = (h ^ w[i]) * UINT64_C(0x9e3779b97f4a7c15);
    h ^= h >> 29;
  }
  return h;
}

static inline int64_t ds1928_shm_now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static inline void ds1928_shm_cpu_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  __asm__ __volatile__("yield");
#endif
}

static inline const struct ds1928_shm_axis* ds1928_shm_axis_record(
    const struct ds1928_shm_header* h, uint32_t axis) {
  return (const struct ds1928_shm_axis*)(const void*)((const char*)h + h->header_size +
                                                      (size_t)axis * h->record_size);
}

/* The seqlock pass of both readers below: the payload and, with `info` (not NULL), the
 * channels' words in the same pass. 0 or -EBUSY. */
static inline int ds1928_shm_copy_record_(const struct ds1928_shm_axis* rec,
                                          struct ds1928_axis_data* out,
                                          struct ds1928_axis_info* info) {
  uint64_t* dst = (uint64_t*)(void*)out;
  uint64_t* idst = (uint64_t*)(void*)info;
  for (unsigned attempt = 0; attempt < 100000u; ++attempt) {
    const uint64_t s1 = __atomic_load_n(&rec->seq, __ATOMIC_ACQUIRE);
    if (s1 & 1u) {
      ds1928_shm_cpu_relax();
      continue;
    }
    for (unsigned i = 0; i < DS1928_AXIS_DATA_WORDS; ++i)
      dst[i] = __atomic_load_n(&rec->u.words[i], __ATOMIC_RELAXED);
    if (idst)
      for (unsigned i = 0; i < DS1928_AXIS_INFO_WORDS; ++i)
        idst[i] = __atomic_load_n(&rec->x.words[i], __ATOMIC_RELAXED);
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    if (__atomic_load_n(&rec->seq, __ATOMIC_RELAXED) == s1) return 0;
  }
  return -EBUSY;
}

/* Consistent copy of one record. Returns 0, -EINVAL for a bad axis, or -EBUSY when the record
 * stayed locked for ~1 ms of retries (only possible if the daemon died in the middle of a
 * write). */
static inline int ds1928_shm_read_axis(const struct ds1928_shm_header* h, uint32_t axis,
                                       struct ds1928_axis_data* out) {
  if (axis >= h->axis_count) return -EINVAL;
  return ds1928_shm_copy_record_(ds1928_shm_axis_record(h, axis), out, NULL);
}

/* The daemon publishes the additional-information channels (DS1928_SHM_FEATURE_INFO). */
static inline int ds1928_shm_has_info(const struct ds1928_shm_header* h) {
  return (__atomic_load_n(&h->features, __ATOMIC_ACQUIRE) & DS1928_SHM_FEATURE_INFO) != 0;
}

/* Consistent copy of one record with its additional-information channels (one seqlock pass).
 * Returns as ds1928_shm_read_axis, and -ENOTSUP when the daemon publishes no channels. */
static inline int ds1928_shm_read_axis_info(const struct ds1928_shm_header* h, uint32_t axis,
                                            struct ds1928_axis_data* out,
                                            struct ds1928_axis_info* info) {
  if (axis >= h->axis_count) return -EINVAL;
  if (!ds1928_shm_has_info(h)) return -ENOTSUP;
  return ds1928_shm_copy_record_(ds1928_shm_axis_record(h, axis), out, info);
}

/* The name of channel `channel` (0-based) of `axis` as axes[].info gives it, or NULL when the
 * daemon publishes no channels, the arguments are out of range or the channel is off. `size` is
 * the mapping's size (ds1928_shm_reader.size). */
static inline const char* ds1928_shm_info_name(const struct ds1928_shm_header* h, size_t size,
                                               uint32_t axis, uint32_t channel) {
  if (!ds1928_shm_has_info(h) || axis >= h->axis_count || channel >= DS1928_INFO_CHANNELS)
    return NULL;
  const uint64_t at = (uint64_t)h->info_names_offset +
                      ((uint64_t)axis * DS1928_INFO_CHANNELS + channel) * DS1928_INFO_NAME_LEN;
  if (h->info_names_offset == 0 || at + DS1928_INFO_NAME_LEN > size) return NULL;
  const char* name = (const char*)h + at;
  if (name[0] == '\0' || memchr(name, '\0', DS1928_INFO_NAME_LEN) == NULL) return NULL;
  return name;
}

static inline uint32_t ds1928_shm_daemon_state(const struct ds1928_shm_header* h) {
  return __atomic_load_n(&h->daemon_state, __ATOMIC_ACQUIRE);
}
static inline uint64_t ds1928_shm_last_cycle(const struct ds1928_shm_header* h) {
  return __atomic_load_n(&h->last_cycle, __ATOMIC_ACQUIRE);
}
static inline int64_t ds1928_shm_last_publish_ns(const struct ds1928_shm_header* h) {
  return __atomic_load_n(&h->last_publish_ns, __ATOMIC_ACQUIRE);
}
static inline uint64_t ds1928_shm_publish_count(const struct ds1928_shm_header* h) {
  return __atomic_load_n(&h->publish_count, __ATOMIC_ACQUIRE);
}

/* The daemon publishes the time base (DS1928_SHM_FEATURE_TIMEBASE). An older daemon leaves
 * `features` 0; a reader then falls back to ds1928_shm_wait(). */
static inline int ds1928_shm_has_timebase(const struct ds1928_shm_header* h) {
  return (__atomic_load_n(&h->features, __ATOMIC_ACQUIRE) & DS1928_SHM_FEATURE_TIMEBASE) != 0;
}

/* The instant (CLOCK_MONOTONIC ns) of the first publication later than `after_ns` whose cycle
 * index is a multiple of `every` (0 counts as 1), predicted from the time base: that cycle's
 * start plus the measured publication offset p99 (the cycle's start alone while no window has
 * been measured yet). An application sleeps with clock_nanosleep(CLOCK_MONOTONIC,
 * TIMER_ABSTIME) until *at_ns plus its own offset, then reads: the record of cycle *cycle is
 * there unless that cycle overran or the daemon is gone (check the record's `cycle`). Pass the
 * *at_ns of one call as `after_ns` of the next to step from publication to publication; when
 * the measured offset grew in between, the same cycle comes back: take the next multiple then
 * (examples/isochronous_loop.c).
 * Returns 0; -ENOTSUP when the daemon publishes no time base; -EAGAIN before its first cycle. */
static inline int ds1928_shm_next_publication(const struct ds1928_shm_header* h, int64_t after_ns,
                                              uint32_t every, int64_t* at_ns, uint64_t* cycle) {
  if (!ds1928_shm_has_timebase(h)) return -ENOTSUP;
  const int64_t t0 = __atomic_load_n(&h->timebase_t0_ns, __ATOMIC_ACQUIRE);
  const int64_t period = (int64_t)h->cycle_period_ns;
  if (t0 == 0 || period <= 0) return -EAGAIN;
  const int64_t offset = (int64_t)__atomic_load_n(&h->publish_offset_p99_ns, __ATOMIC_ACQUIRE);
  if (every == 0) every = 1;
  const int64_t step = period * (int64_t)every;
  /* First multiple of `every` whose publication lies after after_ns. */
  const int64_t rel = after_ns - offset - t0;
  const int64_t k = rel < 0 ? 0 : rel / step + 1;
  *cycle = (uint64_t)k * every;
  *at_ns = t0 + k * step + offset;
  return 0;
}

/* "Nothing seen yet": the starting value for ds1928_shm_wait's *seen_cycle before the first
 * publication. */
#define DS1928_SHM_NO_CYCLE UINT64_MAX

/* The starting value of ds1928_shm_wait's *seen_cycle: the last published cycle, so that the
 * first wait returns at the next publication. */
static inline uint64_t ds1928_shm_wait_start(const struct ds1928_shm_header* h) {
  return ds1928_shm_publish_count(h) != 0 ? ds1928_shm_last_cycle(h) : DS1928_SHM_NO_CYCLE;
}

/* True when a publication with a cycle index that is a multiple of `every` happened after
 * `seen_cycle` (a multiple lies in (seen_cycle, last]; with DS1928_SHM_NO_CYCLE: the last
 * publication's index is a multiple). */
static inline int ds1928_shm_due(const struct ds1928_shm_header* h, uint64_t seen_cycle,
                                 uint32_t every, uint64_t* last) {
  if (ds1928_shm_publish_count(h) == 0) return 0;
  const uint64_t cycle = ds1928_shm_last_cycle(h);
  *last = cycle;
  if (seen_cycle == DS1928_SHM_NO_CYCLE) return cycle % every == 0;
  return cycle > seen_cycle && cycle / every > seen_cycle / every;
}

/* True while the daemon publishes: not stopped, and the last publication is younger than
 * `missed_cycles` cycle periods (at least 100 ms, to ride over scheduling hiccups). A daemon
 * that is still starting counts as alive for the same time after creation is seen. */
static inline int ds1928_shm_daemon_alive(const struct ds1928_shm_header* h, int64_t now_ns,
                                          uint32_t missed_cycles) {
  if (ds1928_shm_daemon_state(h) == DS1928_DAEMON_STOPPED) return 0;
  const int64_t last = ds1928_shm_last_publish_ns(h);
  if (last == 0) return 1;
  int64_t tolerance = (int64_t)h->cycle_period_ns * (int64_t)missed_cycles;
  if (tolerance < 100000000) tolerance = 100000000;
  return now_ns - last <= tolerance;
}

/* A mapped daemon instance. */
struct ds1928_shm_reader {
  const struct ds1928_shm_header* header; /* NULL when closed */
  size_t size;
  struct ds1928_shm_wait_area* wait; /* NULL when <name>.wait could not be opened read-write */
  uint64_t generation;
};

static inline void ds1928_shm_reader_close(struct ds1928_shm_reader* r) {
  if (r->header) munmap((void*)(uintptr_t)r->header, r->size);
  if (r->wait) munmap(r->wait, sizeof(struct ds1928_shm_wait_area));
  r->header = NULL;
  r->wait = NULL;
  r->size = 0;
  r->generation = 0;
}

/* Maps <name> read-only and <name>.wait read-write (optional: without it ds1928_shm_wait
 * returns -ENOTSUP). Returns 0; -errno of shm_open/mmap (-ENOENT: no daemon); -EAGAIN while the
 * daemon is still creating the object; -EPROTO for a foreign object or another ABI version. */
static inline int ds1928_shm_reader_open(struct ds1928_shm_reader* r, const char* name) {
  r->header = NULL;
  r->wait = NULL;
  r->size = 0;
  r->generation = 0;
  /* O_NONBLOCK: a FIFO planted under the name must not block the reader (glibc adds
   * O_NOFOLLOW: a symbolic link fails with ELOOP). */
  int fd = shm_open(name, O_RDONLY | O_NONBLOCK | O_CLOEXEC, 0);
  if (fd < 0) return -errno;
  struct stat st;
  if (fstat(fd, &st) != 0) {
    int e = -errno;
    close(fd);
    return e;
  }
  if (!S_ISREG(st.st_mode)) {
    close(fd);
    return -EINVAL;
  }
  if ((size_t)st.st_size < sizeof(struct ds1928_shm_header)) {
    close(fd);
    return -EAGAIN; /* created, not yet sized */
  }
  void* p = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_SHARED, fd, 0);
  close(fd);
  if (p == MAP_FAILED) return -errno;
  const struct ds1928_shm_header* h = (const struct ds1928_shm_header*)p;
  r->header = h;
  r->size = (size_t)st.st_size;
  const uint64_t magic = __atomic_load_n(&h->magic, __ATOMIC_ACQUIRE);
  if (magic == 0) {
    ds1928_shm_reader_close(r);
    return -EAGAIN;
  }
  if (magic != DS1928_SHM_MAGIC || h->abi_version != DS1928_SHM_ABI_VERSION ||
      h->header_size < sizeof(struct ds1928_shm_header) ||
      h->record_size < sizeof(struct ds1928_shm_axis) ||
      (uint64_t)h->header_size + (uint64_t)h->axis_count * h->record_size > r->size) {
    ds1928_shm_reader_close(r);
    return -EPROTO;
  }
  r->generation = h->generation;

  char wait_name[DS1928_SHM_NAME_MAX + 1];
  const size_t len = strlen(name);
  if (len + sizeof(DS1928_SHM_WAIT_SUFFIX) <= sizeof(wait_name)) {
    memcpy(wait_name, name, len);
    memcpy(wait_name + len, DS1928_SHM_WAIT_SUFFIX, sizeof(DS1928_SHM_WAIT_SUFFIX));
    int wfd = shm_open(wait_name, O_RDWR | O_CLOEXEC, 0);
    if (wfd >= 0) {
      void* w = mmap(NULL, sizeof(struct ds1928_shm_wait_area), PROT_READ | PROT_WRITE, MAP_SHARED,
                     wfd, 0);
      close(wfd);
      if (w != MAP_FAILED) {
        struct ds1928_shm_wait_area* wa = (struct ds1928_shm_wait_area*)w;
        if (__atomic_load_n(&wa->magic, __ATOMIC_ACQUIRE) == DS1928_SHM_WAIT_MAGIC &&
            wa->generation == r->generation) {
          r->wait = wa;
        } else {
          munmap(w, sizeof(struct ds1928_shm_wait_area));
        }
      }
    }
  }
  return 0;
}

/* For a reader whose daemon looks dead or stopped: maps <name> again. Returns 1 when a new
 * daemon generation is now mapped, 0 when the name still holds the same generation (or the new
 * one is not ready yet), -errno when the name cannot be opened (the old mapping is kept). */
static inline int ds1928_shm_reader_reopen(struct ds1928_shm_reader* r, const char* name) {
  struct ds1928_shm_reader fresh;
  int rc = ds1928_shm_reader_open(&fresh, name);
  if (rc == -EAGAIN) return 0;
  if (rc != 0) return rc;
  if (fresh.generation == r->generation) {
    ds1928_shm_reader_close(&fresh);
    return 0;
  }
  ds1928_shm_reader_close(r);
  *r = fresh;
  return 1;
}

/* Claims (or finds) the wait slot for `factor`; falls back to a factor-1 slot filtered by the
 * reader when all slots hold other factors. Returns the slot index or -1. */
static inline int ds1928_shm_wait_slot_for(struct ds1928_shm_wait_area* w, uint32_t factor) {
  for (unsigned pass = 0; pass < 2; ++pass) {
    for (unsigned i = 0; i < DS1928_SHM_WAIT_SLOTS; ++i) {
      uint32_t f = __atomic_load_n(&w->slots[i].factor, __ATOMIC_ACQUIRE);
      if (f == factor) return (int)i;
      if (f == 0) {
        uint32_t expected = 0;
        if (__atomic_compare_exchange_n(&w->slots[i].factor, &expected, factor, 0, __ATOMIC_SEQ_CST,
                                        __ATOMIC_ACQUIRE) ||
            expected == factor)
          return (int)i;
      }
    }
    if (factor == 1) break;
    factor = 1;
  }
  return -1;
}

/* Waits for the next publication whose cycle index is a multiple of `every` (1 = every
 * publication, like an application cycle factor). `*seen_cycle` is the cycle index the caller
 * last consumed (ds1928_shm_wait_start() at the start, then the value this function stores);
 * returns at once when a matching publication already happened after it.
 * `deadline_ns` is absolute CLOCK_MONOTONIC. Returns 0 (and updates *seen_cycle to the last
 * published cycle), DS1928_SHM_TIMEOUT, DS1928_SHM_STOPPED, -ENOTSUP without a wait area,
 * -EINTR on a signal. */
static inline int ds1928_shm_wait(const struct ds1928_shm_reader* r, uint64_t* seen_cycle,
                                  uint32_t every, int64_t deadline_ns) {
  const struct ds1928_shm_header* h = r->header;
  struct ds1928_shm_wait_area* w = r->wait;
  if (!w) return -ENOTSUP;
  if (every == 0) every = 1;
  const int slot = ds1928_shm_wait_slot_for(w, every);
  if (slot < 0) return -ENOTSUP;
  const uint32_t mask = 1u << (unsigned)slot;
  int rc = 0;
  for (;;) {
    /* Register before looking: the daemon stores the futex word, then reads the waiter counts
     * (both sequentially consistent), so either it sees us or we see its new value. */
    __atomic_fetch_add(&w->slots[slot].waiters, 1u, __ATOMIC_SEQ_CST);
    const uint32_t val = __atomic_load_n(&w->futex, __ATOMIC_SEQ_CST);
    uint64_t cycle = 0;
    if (ds1928_shm_due(h, *seen_cycle, every, &cycle)) {
      *seen_cycle = cycle;
      rc = 0;
    } else if (ds1928_shm_daemon_state(h) == DS1928_DAEMON_STOPPED) {
      rc = DS1928_SHM_STOPPED;
    } else {
      struct timespec ts;
      ts.tv_sec = (time_t)(deadline_ns / 1000000000);
      ts.tv_nsec = (long)(deadline_ns % 1000000000);
      long k = syscall(SYS_futex, &w->futex, FUTEX_WAIT_BITSET, val, &ts, NULL, mask);
      int e = k == 0 ? 0 : errno;
      __atomic_fetch_sub(&w->slots[slot].waiters, 1u, __ATOMIC_SEQ_CST);
      if (e == ETIMEDOUT) return DS1928_SHM_TIMEOUT;
      if (e == EINTR) return -EINTR;
      if (e != 0 && e != EAGAIN) return -e;
      continue; /* woken or the word changed: look again */
    }
    __atomic_fetch_sub(&w->slots[slot].waiters, 1u, __ATOMIC_SEQ_CST);
    return rc;
  }
}

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* DS1928_SHM_H */
