/* ds1928: LinuxCNC HAL component (uspace) that reads the positions ds1928d publishes in shared
 * memory (include/ds1928/shm.h, docs/shared-memory.md) into HAL pins. docs/linuxcnc.md is the
 * user's guide; this comment is the design.
 *
 *   loadrt ds1928 [shm=/ds1928d[,/other...]] [names=ds1928[,...]] [axes=x:y[,...]]
 *                 [sync=0[,1...]] [sync_period_ns=N]
 *   addf ds1928.read servo-thread
 *
 * sync=1 (one instance at most): `ds1928.read` steers the thread it runs in with the RTAPI task
 * PLL (rtapi_task_pll_get_reference / rtapi_task_pll_set_correction, uspace only) so that each
 * period starts at a fixed phase of the daemon's bus cycle: the published time base (cycle n
 * starts at t0 + n·T_bus) plus the measured publication offset plus sync-offset-us. The thread
 * and the daemon run on the same CLOCK_MONOTONIC, so only the phase is to be corrected: a
 * proportional step per period, bounded to 1 % of the period (what uspace's rtapi allows) and
 * slewed by at most 0.1 % of the period per period. Both periods must be whole multiples of one
 * another; the phase is then taken modulo the shorter one.
 *
 * One instance per daemon (per shm name). The realtime function `ds1928.read` reads every axis
 * of every instance with the seqlock of the header (a bounded number of attempts, each copy also
 * checked against its check word), and otherwise only stores pins: no lock, no allocation, no
 * system call (the clock is CLOCK_MONOTONIC through the vDSO).
 *
 * Everything that needs system calls (shm_open, mmap, munmap) happens in one helper thread of
 * normal priority: it maps the daemon's object when it appears, and when the daemon stops or dies
 * and a new one (new generation) publishes under the name, it maps the new object, hands it to
 * the realtime function through an atomic pointer and unmaps the old one once no invocation of
 * the function that may have loaded the old pointer is still running (the enter/exit counters
 * below). The realtime function never waits for the helper: until the handover its pins say
 * invalid. */
/* The loadrt parameter `sync` is a variable of that name: <unistd.h>'s sync() is renamed while
 * the headers are read. */
#define sync ds1928_unistd_sync
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>

#include "ds1928/shm.h"
#include "hal.h"
#include "rtapi.h"
#include "rtapi_app.h"
#undef sync

MODULE_AUTHOR("ds1928d");
MODULE_DESCRIPTION("ds1928d shared-memory positions (X20DS1928 EnDat) as HAL pins");
MODULE_LICENSE("Proprietary"); /* packaging/debian/copyright */

#define MAX_INSTANCES 8
#define MAX_AXES 64
#define NAME_LEN 48
/* Attempts of one seqlock copy in the realtime function. A daemon write takes ~100 ns; more than
 * a few consecutive failures means a writer that died in the middle of a record. */
#define READ_ATTEMPTS 8

static char* shm[MAX_INSTANCES] = {DS1928_SHM_DEFAULT_NAME};
RTAPI_MP_ARRAY_STRING(shm, MAX_INSTANCES, "shared memory names of the daemons, one instance each");
static char* names[MAX_INSTANCES];
RTAPI_MP_ARRAY_STRING(names, MAX_INSTANCES,
                      "pin prefix of each instance (default ds1928, ds1928-1, ...)");
static char* axes[MAX_INSTANCES];
RTAPI_MP_ARRAY_STRING(axes, MAX_INSTANCES,
                      "axis names of each instance, separated by ':' (default 0, 1, ... "
                      "for every axis the daemon has at load time)");

static int sync[MAX_INSTANCES];
RTAPI_MP_ARRAY_INT(sync, MAX_INSTANCES,
                   "1: lock the thread of ds1928.read to this instance's bus cycle (one at most)");
static int sync_period_ns;
RTAPI_MP_INT(sync_period_ns,
             "period of the thread ds1928.read runs in, for the check at load "
             "(default: the RTAPI clock period)");

/* sync: a period's phase error within this many ns (or 1/500 of the aligned period, whichever is
 * more) for kSyncLockPeriods periods in a row is a lock; beyond 4 windows the lock is lost. */
#define SYNC_LOCK_WINDOW_NS 2000
#define SYNC_LOCK_PERIODS 100
/* Default sync-offset-us: the publication's jitter (p99 - p50) plus this margin. */
#define SYNC_DEFAULT_MARGIN_NS 20000

struct sync_pins {
  hal_bit_t* locked;
  hal_float_t* error_us;
  hal_s32_t* correction_ns;
  hal_float_t* phase_us; /* the target: this long after the bus cycle's start */
  hal_u32_t* locks;      /* locks acquired since load (a re-lock counts again) */
  hal_float_t offset_us; /* parameter: after the publication (p50); < 0: p99 - p50 + 20 µs */
};

/* State of the steering, realtime function only. */
struct sync_state {
  int enabled;
  int refused; /* a run-time refusal was reported; steering stays off */
  int locked;
  unsigned good;       /* consecutive periods within the lock window */
  long correction;     /* the correction set last */
  uint64_t generation; /* daemon generation and timeline steered to */
  int64_t t0;
  int64_t phase_ns; /* target phase after the cycle start, latched while unlocked */
  uint32_t locks;
};

struct axis_pins {
  hal_float_t* position;
  hal_u32_t* raw_hi;
  hal_u32_t* raw_lo;
  hal_bit_t* valid;
  hal_bit_t* fresh;
  hal_bit_t* new_position;
  hal_bit_t* stale;
  hal_s32_t* pos_cycle;
  hal_u32_t* error_info;
  hal_u32_t* endat_error;
  hal_u32_t* endat_warning;
  hal_bit_t* fault;   /* a fault-class error bit is set (docs/registers.md, error bits) */
  hal_bit_t* warning; /* a warning-class error bit is set; the position stays valid */
  hal_float_t* age_us;
  /* The additional-information channels the daemon named at load (DS1928_SHM_FEATURE_INFO):
   * <axis>.info-<name> (value), -valid, -age-us; NULL pins where the channel is off. */
  hal_s32_t* info_value[DS1928_INFO_CHANNELS];
  hal_bit_t* info_valid[DS1928_INFO_CHANNELS];
  hal_float_t* info_age_us[DS1928_INFO_CHANNELS];
  hal_float_t scale;  /* parameter: counts (LSBs of the 64-bit position) per user unit */
  hal_float_t offset; /* parameter: added after scaling */
};

struct instance_pins {
  hal_bit_t* daemon_alive;
  hal_u32_t* bus_cycle;
  hal_u32_t* restarts;
  hal_float_t* phase_us;
  hal_float_t* bus_period_us;
  hal_u32_t* read_retries;
  hal_u32_t* read_failures;
  hal_u32_t timeout_us; /* parameter: a daemon silent this long is dead (0: automatic) */
  struct sync_pins sync;
  struct axis_pins axis[];
};

/* A mapped daemon generation, owned by the helper thread. */
struct mapping {
  struct ds1928_shm_reader reader;
};

struct instance {
  char shm_name[DS1928_SHM_NAME_MAX + 1];
  char prefix[NAME_LEN];
  unsigned axis_count;
  struct instance_pins* pins; /* HAL memory */
  struct mapping* current;    /* atomic: what the realtime function reads, NULL = none */
  uint64_t rt_enter;          /* atomic: invocations of the realtime function started */
  uint64_t rt_exit;           /* atomic: ... and finished */
  uint32_t restarts;          /* atomic: generations mapped after the first one */
  uint64_t first_generation;  /* helper only: 0 = nothing mapped yet */
  uint32_t retries;           /* realtime function only */
  uint32_t failures;          /* realtime function only */
  int reported;               /* helper only: last open error printed */
  struct sync_state sync;     /* realtime function only (enabled: set at load) */
};

static int comp_id = -1;
static struct instance instances[MAX_INSTANCES];
static unsigned instance_count;
static pthread_t helper;
static int helper_started;
static int helper_stop; /* atomic */

/* A daemon silent this long is taken for dead: ten bus periods, at least 10 ms (a busy
 * non-PREEMPT_RT kernel delays the daemon's cycle thread by milliseconds now and then). */
static int64_t silence_limit_ns(const struct instance* in, const struct ds1928_shm_header* h) {
  if (in->pins->timeout_us != 0) return (int64_t)in->pins->timeout_us * 1000;
  int64_t limit = 10 * (int64_t)h->cycle_period_ns;
  return limit < 10000000 ? 10000000 : limit;
}

static int daemon_publishing(const struct instance* in, const struct ds1928_shm_header* h,
                             int64_t now) {
  if (ds1928_shm_daemon_state(h) == DS1928_DAEMON_STOPPED) return 0;
  const int64_t last = ds1928_shm_last_publish_ns(h);
  return last != 0 && now - last <= silence_limit_ns(in, h);
}

/* One consistent copy in at most READ_ATTEMPTS tries: seqlock plus check word. With `info`
 * (not NULL) the channels' words are copied in the same pass (the check word covers the payload
 * only; the equal sequence covers both). */
static int read_record(const struct ds1928_shm_axis* rec, struct ds1928_axis_data* out,
                       struct ds1928_axis_info* info, uint32_t* retries) {
  uint64_t* dst = (uint64_t*)(void*)out;
  uint64_t* idst = (uint64_t*)(void*)info;
  for (unsigned attempt = 0; attempt < READ_ATTEMPTS; ++attempt) {
    if (attempt != 0) {
      ++*retries;
      ds1928_shm_cpu_relax();
    }
    const uint64_t s1 = __atomic_load_n(&rec->seq, __ATOMIC_ACQUIRE);
    if (s1 & 1u) continue;
    for (unsigned i = 0; i < DS1928_AXIS_DATA_WORDS; ++i)
      dst[i] = __atomic_load_n(&rec->u.words[i], __ATOMIC_RELAXED);
    if (idst)
      for (unsigned i = 0; i < DS1928_AXIS_INFO_WORDS; ++i)
        idst[i] = __atomic_load_n(&rec->x.words[i], __ATOMIC_RELAXED);
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    if (__atomic_load_n(&rec->seq, __ATOMIC_RELAXED) == s1 && ds1928_shm_check(out) == out->check)
      return 1;
  }
  return 0;
}

static void invalidate(struct instance_pins* p, unsigned from, unsigned to) {
  for (unsigned a = from; a < to; ++a) {
    *p->axis[a].valid = 0;
    *p->axis[a].fresh = 0;
    *p->axis[a].new_position = 0;
    *p->axis[a].stale = 1;
    for (unsigned n = 0; n < DS1928_INFO_CHANNELS; ++n)
      if (p->axis[a].info_valid[n]) *p->axis[a].info_valid[n] = 0;
  }
}

static void read_instance(struct instance* in, int64_t now) {
  struct instance_pins* p = in->pins;
  __atomic_fetch_add(&in->rt_enter, 1, __ATOMIC_SEQ_CST);
  const struct mapping* m = __atomic_load_n(&in->current, __ATOMIC_SEQ_CST);
  *p->restarts = __atomic_load_n(&in->restarts, __ATOMIC_RELAXED);
  if (!m) {
    *p->daemon_alive = 0;
    invalidate(p, 0, in->axis_count);
  } else {
    const struct ds1928_shm_header* h = m->reader.header;
    const int alive = daemon_publishing(in, h, now);
    const int64_t period = (int64_t)h->cycle_period_ns;
    const int64_t last = ds1928_shm_last_publish_ns(h);
    *p->daemon_alive = alive;
    *p->bus_period_us = (double)period / 1000.0;
    if (last != 0 && period > 0) {
      int64_t phase = (now - last) % period;
      if (phase < 0) phase += period;
      *p->phase_us = (double)phase / 1000.0;
    }
    const unsigned present = h->axis_count < in->axis_count ? h->axis_count : in->axis_count;
    const int has_info = ds1928_shm_has_info(h);
    for (unsigned a = 0; a < present; ++a) {
      struct axis_pins* ap = &p->axis[a];
      struct ds1928_axis_data d;
      struct ds1928_axis_info info;
      memset(&info, 0, sizeof info);
      const struct ds1928_shm_axis* rec = ds1928_shm_axis_record(h, a);
      if (!read_record(rec, &d, has_info ? &info : NULL, &in->retries)) {
        ++in->failures; /* keep the last values, but not as valid */
        *ap->valid = 0;
        continue;
      }
      const int64_t counts_hi = d.periods; /* periods carry the daemon's signed/unsigned choice */
      const double counts = (double)counts_hi * 65536.0 + (double)d.fraction;
      const double scale = ap->scale != 0.0 ? ap->scale : 1.0;
      *ap->position = counts / scale + ap->offset;
      *ap->raw_hi = (uint32_t)(d.position_raw >> 32);
      *ap->raw_lo = (uint32_t)d.position_raw;
      *ap->valid = alive && d.validity == DS1928_AXIS_VALID;
      *ap->fresh = alive && (d.flags & DS1928_AXIS_FRESH) != 0;
      *ap->new_position = alive && (d.flags & DS1928_AXIS_NEW_POSITION) != 0;
      *ap->stale = !alive || d.validity == DS1928_AXIS_STALE;
      *ap->pos_cycle = d.pos_cycle;
      *ap->error_info = d.error_info;
      *ap->endat_error = d.endat_error;
      *ap->endat_warning = d.endat_warning;
      *ap->fault = (d.flags & DS1928_AXIS_FAULT) != 0;
      *ap->warning = (d.flags & DS1928_AXIS_WARNING) != 0;
      const int64_t t = d.pos_time_ns != 0 ? d.pos_time_ns : d.publish_ns;
      *ap->age_us = (double)(now - t) / 1000.0;
      for (unsigned n = 0; n < DS1928_INFO_CHANNELS; ++n) {
        if (!ap->info_value[n]) continue;
        *ap->info_value[n] = info.value[n];
        *ap->info_valid[n] = alive && (info.valid & (1u << n)) != 0;
        /* -1: never read valid (or a daemon without the channels) */
        *ap->info_age_us[n] = info.age_us[n] == DS1928_INFO_AGE_NEVER
                                  ? -1.0
                                  : (double)info.age_us[n] + (double)(now - d.publish_ns) / 1000.0;
      }
      if (a == 0) *p->bus_cycle = (uint32_t)d.cycle;
    }
    if (present == 0) *p->bus_cycle = (uint32_t)ds1928_shm_last_cycle(h);
    invalidate(p, present, in->axis_count); /* the new daemon has fewer axes */
  }
  *p->read_retries = in->retries;
  *p->read_failures = in->failures;
  __atomic_fetch_add(&in->rt_exit, 1, __ATOMIC_SEQ_CST);
}

/* Two periods fit when one is a whole multiple of the other. */
static int periods_fit(int64_t servo, int64_t bus) {
  return servo > 0 && bus > 0 && (servo % bus == 0 || bus % servo == 0);
}

#ifdef RTAPI_TASK_PLL_SUPPORT
static void sync_refuse(struct instance* in, const char* why, long servo, int64_t bus) {
  struct sync_state* st = &in->sync;
  st->refused = 1;
  st->locked = 0;
  *in->pins->sync.locked = 0;
  (void)rtapi_task_pll_set_correction(0);
  rtapi_print_msg(RTAPI_MSG_ERR,
                  "ds1928: %s: sync off: %s (thread period %ld ns, bus period %lld ns)\n",
                  in->shm_name, why, servo, (long long)bus);
}

static void sync_unlock(struct sync_state* st) {
  st->locked = 0;
  st->good = 0;
}

/* One period of the steering: the phase of this period's start (the PLL reference, the nominal
 * start on CLOCK_MONOTONIC) against the bus's timeline, and the correction of the next period.
 * While the daemon is gone the last correction is held (locked: ~0, both sides run on the same
 * clock) and the lock is dropped; a new generation or a moved timeline starts a new lock-in. */
static void sync_step(struct instance* in, const struct mapping* m, long period, int64_t now) {
  struct sync_state* st = &in->sync;
  struct sync_pins* sp = &in->pins->sync;
  if (!st->enabled || st->refused) return;
  const long long ref = rtapi_task_pll_get_reference();
  if (ref <= 0) {
    sync_refuse(in, "this RTAPI gives no task PLL reference", period, 0);
    return;
  }
  const struct ds1928_shm_header* h = m ? m->reader.header : NULL;
  if (!h || !daemon_publishing(in, h, now) || !ds1928_shm_has_timebase(h)) {
    if (st->locked) *sp->correction_ns = (hal_s32_t)st->correction; /* held */
    sync_unlock(st);
    *sp->locked = 0;
    return;
  }
  const int64_t bus = (int64_t)h->cycle_period_ns;
  if (!periods_fit(period, bus)) {
    sync_refuse(in, "the periods are not whole multiples of one another", period, bus);
    return;
  }
  const int64_t t0 = __atomic_load_n(&h->timebase_t0_ns, __ATOMIC_ACQUIRE);
  const int64_t p50 = (int64_t)__atomic_load_n(&h->publish_offset_p50_ns, __ATOMIC_ACQUIRE);
  const int64_t p99 = (int64_t)__atomic_load_n(&h->publish_offset_p99_ns, __ATOMIC_ACQUIRE);
  if (t0 == 0 || p99 == 0) return; /* no timeline or no measurement yet */
  if (m->reader.generation != st->generation || t0 != st->t0) {
    st->generation = m->reader.generation;
    st->t0 = t0;
    sync_unlock(st);
  }
  if (!st->locked) {
    const int64_t offset = sp->offset_us >= 0.0 ? (int64_t)(sp->offset_us * 1000.0)
                                                : p99 - p50 + SYNC_DEFAULT_MARGIN_NS;
    st->phase_ns = p50 + offset;
  }
  const int64_t aligned = period < bus ? period : bus;
  int64_t err = (ref - (t0 + st->phase_ns)) % aligned;
  if (err < 0) err += aligned;
  if (err >= aligned / 2) err -= aligned;

  /* Proportional: half the error per period (the correction lengthens or shortens the next
   * period, so the error shrinks by it), bounded and slewed. */
  const long bound = period / 100;
  const long slew = period / 1000 > 0 ? period / 1000 : 1;
  long want = (long)(-err / 2);
  if (want > bound) want = bound;
  if (want < -bound) want = -bound;
  if (want > st->correction + slew) want = st->correction + slew;
  if (want < st->correction - slew) want = st->correction - slew;
  st->correction = want;
  (void)rtapi_task_pll_set_correction(want);

  const int64_t window = aligned / 500 > SYNC_LOCK_WINDOW_NS ? aligned / 500 : SYNC_LOCK_WINDOW_NS;
  const int64_t mag = err < 0 ? -err : err;
  if (mag <= window) {
    if (!st->locked && ++st->good >= SYNC_LOCK_PERIODS) {
      st->locked = 1;
      ++st->locks;
    }
  } else if (!st->locked || mag > 4 * window) {
    sync_unlock(st);
  }
  *sp->locked = st->locked;
  *sp->error_us = (double)err / 1000.0;
  *sp->correction_ns = (hal_s32_t)want;
  *sp->phase_us = (double)st->phase_ns / 1000.0;
  *sp->locks = st->locks;
}
#else
/* sync=1 is refused at load where the RTAPI has no task PLL. */
static void sync_step(struct instance* in, const struct mapping* m, long period, int64_t now) {
  (void)in;
  (void)m;
  (void)period;
  (void)now;
}
#endif

/* The realtime function: every instance, once per thread period. */
static void read_all(void* arg, long period) {
  (void)arg;
  const int64_t now = ds1928_shm_now_ns(); /* vDSO: no system call */
  for (unsigned i = 0; i < instance_count; ++i) {
    struct instance* in = &instances[i];
    read_instance(in, now);
    if (in->sync.enabled) {
      /* The mapping read_instance used may be replaced meanwhile: count this use too. */
      __atomic_fetch_add(&in->rt_enter, 1, __ATOMIC_SEQ_CST);
      sync_step(in, __atomic_load_n(&in->current, __ATOMIC_SEQ_CST), period, now);
      __atomic_fetch_add(&in->rt_exit, 1, __ATOMIC_SEQ_CST);
    }
  }
}

/* ---- helper thread (normal priority; the only place with system calls) ---- */

static void sleep_ms(long ms) {
  struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}

/* Publishes `m` to the realtime function and unmaps what it replaces once no invocation that may
 * have loaded the old pointer runs any more: an invocation counts itself in rt_enter before it
 * loads the pointer, so every one that can see the old mapping started before `started` was read
 * below, and the function runs on one thread at a time. */
static void hand_over(struct instance* in, struct mapping* m) {
  struct mapping* old = __atomic_exchange_n(&in->current, m, __ATOMIC_SEQ_CST);
  if (!old) return;
  const uint64_t started = __atomic_load_n(&in->rt_enter, __ATOMIC_SEQ_CST);
  while (__atomic_load_n(&in->rt_exit, __ATOMIC_SEQ_CST) < started) sleep_ms(1);
  ds1928_shm_reader_close(&old->reader);
  free(old);
}

static const char* open_problem(int rc) {
  switch (rc) {
    case -ENOENT:
      return "no such shared memory (is ds1928d running?)";
    case -EACCES:
      return "permission denied (shm.group / shm.mode of the daemon's configuration)";
    case -EPROTO:
      return "not ds1928d shared memory of this ABI version";
    default:
      return strerror(-rc);
  }
}

/* Maps a new generation under the instance's name if there is one. */
static void try_attach(struct instance* in) {
  struct mapping* m = (struct mapping*)calloc(1, sizeof *m);
  if (!m) return;
  const int rc = ds1928_shm_reader_open(&m->reader, in->shm_name);
  const struct mapping* cur = __atomic_load_n(&in->current, __ATOMIC_SEQ_CST);
  if (rc != 0 || (cur && m->reader.generation == cur->reader.generation)) {
    if (rc != 0 && rc != -EAGAIN && rc != in->reported)
      rtapi_print_msg(RTAPI_MSG_ERR, "ds1928: %s: %s\n", in->shm_name, open_problem(rc));
    if (rc != -EAGAIN) in->reported = rc;
    if (rc == 0) ds1928_shm_reader_close(&m->reader);
    free(m);
    return;
  }
  in->reported = 0;
  if (in->first_generation == 0) {
    in->first_generation = m->reader.generation;
  } else {
    __atomic_fetch_add(&in->restarts, 1, __ATOMIC_SEQ_CST);
  }
  if (m->reader.header->axis_count < in->axis_count)
    rtapi_print_msg(RTAPI_MSG_ERR, "ds1928: %s: the daemon has %u axes, %u are configured\n",
                    in->shm_name, m->reader.header->axis_count, in->axis_count);
  rtapi_print_msg(RTAPI_MSG_INFO, "ds1928: %s: attached to generation %llu\n", in->shm_name,
                  (unsigned long long)m->reader.generation);
  hand_over(in, m);
}

static void* helper_main(void* arg) {
  (void)arg;
  while (!__atomic_load_n(&helper_stop, __ATOMIC_SEQ_CST)) {
    const int64_t now = ds1928_shm_now_ns();
    for (unsigned i = 0; i < instance_count; ++i) {
      struct instance* in = &instances[i];
      const struct mapping* cur = __atomic_load_n(&in->current, __ATOMIC_SEQ_CST);
      if (!cur || !daemon_publishing(in, cur->reader.header, now)) try_attach(in);
    }
    sleep_ms(20);
  }
  return NULL;
}

/* ---- loading ---- */

/* The channels' names of each axis, taken from the daemon at load (loading is single-threaded). */
static char info_names[MAX_AXES][DS1928_INFO_CHANNELS][DS1928_INFO_NAME_LEN];

static int export_axis(const char* prefix, const char* axis, unsigned index, struct axis_pins* p) {
  int r = 0;
  for (unsigned n = 0; n < DS1928_INFO_CHANNELS; ++n) {
    const char* name = info_names[index][n];
    if (!name[0]) continue;
    r |= hal_pin_s32_newf(HAL_OUT, &p->info_value[n], comp_id, "%s.%s.info-%s", prefix, axis, name);
    r |= hal_pin_bit_newf(HAL_OUT, &p->info_valid[n], comp_id, "%s.%s.info-%s-valid", prefix, axis,
                          name);
    r |= hal_pin_float_newf(HAL_OUT, &p->info_age_us[n], comp_id, "%s.%s.info-%s-age-us", prefix,
                            axis, name);
    if (r != 0) return -1;
    *p->info_age_us[n] = -1.0;
  }
  r |= hal_pin_float_newf(HAL_OUT, &p->position, comp_id, "%s.%s.position", prefix, axis);
  r |= hal_pin_u32_newf(HAL_OUT, &p->raw_hi, comp_id, "%s.%s.raw-hi", prefix, axis);
  r |= hal_pin_u32_newf(HAL_OUT, &p->raw_lo, comp_id, "%s.%s.raw-lo", prefix, axis);
  r |= hal_pin_bit_newf(HAL_OUT, &p->valid, comp_id, "%s.%s.valid", prefix, axis);
  r |= hal_pin_bit_newf(HAL_OUT, &p->fresh, comp_id, "%s.%s.fresh", prefix, axis);
  r |= hal_pin_bit_newf(HAL_OUT, &p->new_position, comp_id, "%s.%s.new-position", prefix, axis);
  r |= hal_pin_bit_newf(HAL_OUT, &p->stale, comp_id, "%s.%s.stale", prefix, axis);
  r |= hal_pin_s32_newf(HAL_OUT, &p->pos_cycle, comp_id, "%s.%s.pos-cycle", prefix, axis);
  r |= hal_pin_u32_newf(HAL_OUT, &p->error_info, comp_id, "%s.%s.error-info", prefix, axis);
  r |= hal_pin_u32_newf(HAL_OUT, &p->endat_error, comp_id, "%s.%s.endat-error", prefix, axis);
  r |= hal_pin_u32_newf(HAL_OUT, &p->endat_warning, comp_id, "%s.%s.endat-warning", prefix, axis);
  r |= hal_pin_bit_newf(HAL_OUT, &p->fault, comp_id, "%s.%s.fault", prefix, axis);
  r |= hal_pin_bit_newf(HAL_OUT, &p->warning, comp_id, "%s.%s.warning", prefix, axis);
  r |= hal_pin_float_newf(HAL_OUT, &p->age_us, comp_id, "%s.%s.age-us", prefix, axis);
  r |= hal_param_float_newf(HAL_RW, &p->scale, comp_id, "%s.%s.scale", prefix, axis);
  r |= hal_param_float_newf(HAL_RW, &p->offset, comp_id, "%s.%s.offset", prefix, axis);
  if (r != 0) return -1;
  p->scale = 1.0;
  p->offset = 0.0;
  *p->stale = 1;
  return 0;
}

/* sync=1 at load: refused without a task PLL, with a daemon that publishes no time base, or when
 * the thread's period and the bus period do not fit (both known: the daemon runs, and
 * sync_period_ns or the RTAPI clock gives the thread's). What is not known here is checked at
 * the thread's first period. */
static int sync_check(const struct instance* in, int64_t bus_period, int has_timebase) {
#ifndef RTAPI_TASK_PLL_SUPPORT
  (void)bus_period;
  (void)has_timebase;
  rtapi_print_msg(RTAPI_MSG_ERR,
                  "ds1928: %s: sync=1 refused: this RTAPI has no task PLL "
                  "(rtapi_task_pll_*: LinuxCNC uspace only, not the kernel realtime builds)\n",
                  in->shm_name);
  return -1;
#else
  if (!has_timebase) {
    rtapi_print_msg(RTAPI_MSG_ERR,
                    "ds1928: %s: sync=1 refused: the daemon publishes no time base (an older "
                    "ds1928d)\n",
                    in->shm_name);
    return -1;
  }
  const long servo = sync_period_ns > 0 ? (long)sync_period_ns : rtapi_clock_set_period(0);
  if (servo > 0 && bus_period > 0 && !periods_fit(servo, bus_period)) {
    rtapi_print_msg(RTAPI_MSG_ERR,
                    "ds1928: %s: sync=1 refused: the thread period %ld ns and the bus period "
                    "%lld ns are not whole multiples of one another (servo = k x bus or bus = "
                    "k x servo, k = 1, 2, ...)\n",
                    in->shm_name, servo, (long long)bus_period);
    return -1;
  }
  return 0;
#endif
}

/* Axis names of instance i: the axes= entry split at ':', else 0..n-1 for the n axes the daemon
 * has now (read by mapping it once here). */
static int setup_instance(unsigned i, struct instance* in) {
  static char axis_names[MAX_AXES][NAME_LEN]; /* loading is single-threaded */
  unsigned n = 0;
  int64_t bus_period = 0; /* known when the daemon runs at load */
  int has_timebase = 1;
  snprintf(in->shm_name, sizeof in->shm_name, "%s", shm[i]);
  if (names[i] && names[i][0])
    snprintf(in->prefix, sizeof in->prefix, "%s", names[i]);
  else if (i == 0)
    snprintf(in->prefix, sizeof in->prefix, "ds1928");
  else
    snprintf(in->prefix, sizeof in->prefix, "ds1928-%u", i);
  if (axes[i] && axes[i][0]) {
    const char* s = axes[i];
    while (*s) {
      const char* e = strchr(s, ':');
      const size_t len = e ? (size_t)(e - s) : strlen(s);
      if (len == 0 || len >= NAME_LEN || n == MAX_AXES) {
        rtapi_print_msg(RTAPI_MSG_ERR, "ds1928: axes=%s: empty or too long name, or more than %d\n",
                        axes[i], MAX_AXES);
        return -1;
      }
      memcpy(axis_names[n], s, len);
      axis_names[n][len] = '\0';
      ++n;
      s += len + (e ? 1 : 0);
    }
  } else {
    struct ds1928_shm_reader r;
    int rc = ds1928_shm_reader_open(&r, in->shm_name);
    for (int tries = 0; rc == -EAGAIN && tries < 20; ++tries) {
      sleep_ms(50);
      rc = ds1928_shm_reader_open(&r, in->shm_name);
    }
    if (rc != 0) {
      rtapi_print_msg(RTAPI_MSG_ERR,
                      "ds1928: %s: %s; start ds1928d before loading, or name the axes with "
                      "axes=NAME:NAME...\n",
                      in->shm_name, open_problem(rc));
      return -1;
    }
    n = r.header->axis_count < MAX_AXES ? r.header->axis_count : MAX_AXES;
    bus_period = (int64_t)r.header->cycle_period_ns;
    has_timebase = ds1928_shm_has_timebase(r.header);
    ds1928_shm_reader_close(&r);
    for (unsigned a = 0; a < n; ++a) snprintf(axis_names[a], NAME_LEN, "%u", a);
  }
  if (sync[i] && bus_period == 0) { /* axes named: the daemon's period if it runs already */
    struct ds1928_shm_reader r;
    if (ds1928_shm_reader_open(&r, in->shm_name) == 0) {
      bus_period = (int64_t)r.header->cycle_period_ns;
      has_timebase = ds1928_shm_has_timebase(r.header);
      ds1928_shm_reader_close(&r);
    }
  }
  /* The additional-information channels' names, when the daemon runs at load. */
  memset(info_names, 0, sizeof info_names);
  {
    struct ds1928_shm_reader r;
    if (ds1928_shm_reader_open(&r, in->shm_name) == 0) {
      for (unsigned a = 0; a < n && a < r.header->axis_count; ++a)
        for (unsigned c = 0; c < DS1928_INFO_CHANNELS; ++c) {
          const char* name = ds1928_shm_info_name(r.header, r.size, a, c);
          if (name) snprintf(info_names[a][c], DS1928_INFO_NAME_LEN, "%s", name);
        }
      ds1928_shm_reader_close(&r);
    }
  }
  if (sync[i] && sync_check(in, bus_period, has_timebase) != 0) return -1;
  in->sync.enabled = sync[i] != 0;
  in->axis_count = n;
  in->pins = (struct instance_pins*)hal_malloc(
      (long)(sizeof(struct instance_pins) + n * sizeof(struct axis_pins)));
  if (!in->pins) return -1;
  memset(in->pins, 0, sizeof(struct instance_pins) + n * sizeof(struct axis_pins));
  struct instance_pins* p = in->pins;
  const char* pre = in->prefix;
  int r = 0;
  r |= hal_pin_bit_newf(HAL_OUT, &p->daemon_alive, comp_id, "%s.daemon-alive", pre);
  r |= hal_pin_u32_newf(HAL_OUT, &p->bus_cycle, comp_id, "%s.bus-cycle", pre);
  r |= hal_pin_u32_newf(HAL_OUT, &p->restarts, comp_id, "%s.restarts", pre);
  r |= hal_pin_float_newf(HAL_OUT, &p->phase_us, comp_id, "%s.phase-us", pre);
  r |= hal_pin_float_newf(HAL_OUT, &p->bus_period_us, comp_id, "%s.bus-period-us", pre);
  r |= hal_pin_u32_newf(HAL_OUT, &p->read_retries, comp_id, "%s.read-retries", pre);
  r |= hal_pin_u32_newf(HAL_OUT, &p->read_failures, comp_id, "%s.read-failures", pre);
  r |= hal_param_u32_newf(HAL_RW, &p->timeout_us, comp_id, "%s.timeout-us", pre);
  if (r != 0) return -1;
  if (in->sync.enabled) {
    struct sync_pins* sp = &p->sync;
    r |= hal_pin_bit_newf(HAL_OUT, &sp->locked, comp_id, "%s.sync-locked", pre);
    r |= hal_pin_float_newf(HAL_OUT, &sp->error_us, comp_id, "%s.sync-error-us", pre);
    r |= hal_pin_s32_newf(HAL_OUT, &sp->correction_ns, comp_id, "%s.sync-correction-ns", pre);
    r |= hal_pin_float_newf(HAL_OUT, &sp->phase_us, comp_id, "%s.sync-phase-us", pre);
    r |= hal_pin_u32_newf(HAL_OUT, &sp->locks, comp_id, "%s.sync-locks", pre);
    r |= hal_param_float_newf(HAL_RW, &sp->offset_us, comp_id, "%s.sync-offset-us", pre);
    if (r != 0) return -1;
    sp->offset_us = -1.0;
  }
  for (unsigned a = 0; a < n; ++a)
    if (export_axis(pre, axis_names[a], a, &p->axis[a]) != 0) return -1;
  return 0;
}

int rtapi_app_main(void) {
  comp_id = hal_init("ds1928");
  if (comp_id < 0) return comp_id;
  instance_count = 0;
  unsigned leaders = 0;
  for (unsigned i = 0; i < MAX_INSTANCES; ++i) leaders += sync[i] != 0;
  if (leaders > 1) {
    rtapi_print_msg(RTAPI_MSG_ERR, "ds1928: sync=1 on %u instances: one thread follows one bus\n",
                    leaders);
    hal_exit(comp_id);
    return -EINVAL;
  }
  for (unsigned i = 0; i < MAX_INSTANCES && shm[i] && shm[i][0]; ++i) {
    if (strlen(shm[i]) >= sizeof instances[i].shm_name || shm[i][0] != '/') {
      rtapi_print_msg(RTAPI_MSG_ERR, "ds1928: shm=%s: a POSIX shm name starts with '/'\n", shm[i]);
      hal_exit(comp_id);
      return -EINVAL;
    }
    if (setup_instance(i, &instances[i]) != 0) {
      hal_exit(comp_id);
      return -EINVAL;
    }
    instance_count = i + 1;
  }
  if (hal_export_funct("ds1928.read", read_all, NULL, 1, 0, comp_id) != 0) {
    hal_exit(comp_id);
    return -EINVAL;
  }
  /* The first mapping before any thread runs: pins are right from the first period. */
  for (unsigned i = 0; i < instance_count; ++i) try_attach(&instances[i]);
  __atomic_store_n(&helper_stop, 0, __ATOMIC_SEQ_CST);
  if (pthread_create(&helper, NULL, helper_main, NULL) != 0) {
    rtapi_print_msg(RTAPI_MSG_ERR, "ds1928: cannot start the attach thread\n");
    hal_exit(comp_id);
    return -ENOMEM;
  }
  helper_started = 1;
  hal_ready(comp_id);
  return 0;
}

void rtapi_app_exit(void) {
  if (helper_started) {
    __atomic_store_n(&helper_stop, 1, __ATOMIC_SEQ_CST);
    pthread_join(helper, NULL);
    helper_started = 0;
  }
  /* Remove the function from its thread first, then wait (bounded) for an invocation that was
   * already running, and only then unmap what it reads. */
  hal_exit(comp_id);
  for (int waited = 0; waited < 100; ++waited) {
    int running = 0;
    for (unsigned i = 0; i < instance_count; ++i)
      running |= __atomic_load_n(&instances[i].rt_enter, __ATOMIC_SEQ_CST) !=
                 __atomic_load_n(&instances[i].rt_exit, __ATOMIC_SEQ_CST);
    if (!running) break;
    sleep_ms(1);
  }
  for (unsigned i = 0; i < instance_count; ++i) {
    struct mapping* m = __atomic_exchange_n(&instances[i].current, NULL, __ATOMIC_SEQ_CST);
    if (m) {
      ds1928_shm_reader_close(&m->reader);
      free(m);
    }
  }
}
