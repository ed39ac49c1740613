"""Reader of ds1928d's shared memory (ABI version 1, include/ds1928/shm.h).

The layout is read with struct at the offsets of the C header; every value that changes at run
time is read as one aligned 8-byte (or 4-byte) load from the mapping (memoryview.cast), which the
CPU performs as a single access, so the seqlock protocol of the header holds: read `seq`, copy
the nine payload words, read `seq` again; equal and even means consistent. The copy must also
match its check word. Python cannot order loads with fences the way C's atomics do, so the check
word is what makes a copy trustworthy here: a copy that passes the seqlock but not the check is
retried like a torn one.
"""
import ctypes
import ctypes.util
import errno
import mmap
import os
import struct
import time
from dataclasses import dataclass
from typing import Optional

SHM_MAGIC = 0x4D48533832393144  # "D1928SHM"
WAIT_MAGIC = 0x5449415738323944  # "D928WAIT"
ABI_VERSION = 1
DEFAULT_NAME = "/ds1928d"
WAIT_SUFFIX = ".wait"
WAIT_SLOTS = 16
HEADER_SIZE = 128
RECORD_SIZE = 128
WAIT_SIZE = 256
DATA_WORDS = 9

# Header: magic, abi_version, header_size, record_size, axis_count, generation, cycle_period_ns,
# daemon_pid (offsets 0..44); run-time words at 64 (state u32), 72, 80, 88.
_HEADER_CONST = struct.Struct("<QIIIIQQi")
_PAYLOAD = struct.Struct("<QqqqQiIIIHBbBBBBQ")  # struct ds1928_axis_data, 72 bytes

VALIDITY = {0: "valid", 1: "stale", 2: "bus_down", 3: "module_error"}
TIME_SOURCE = {0: "none", 1: "nettime", 2: "rx_timestamp"}
STATE = {0: "starting", 1: "running", 2: "stopping", 3: "stopped"}
FLAG_NEW_POSITION, FLAG_FRACTION_VALID, FLAG_FRESH = 0x01, 0x02, 0x04
FEATURE_TIMEBASE = 0x01  # header.features: the time base fields are published
FEATURE_INFO = 0x02  # header.features: the additional-information channels are published
INFO_CHANNELS = 4
INFO_NAME_LEN = 32
INFO_AGE_NEVER = 0xFFFFFFFF
INFO_WORDS = 5  # struct ds1928_axis_info, at record offset 88 (word 11), under the seqlock
_INFO = struct.Struct("<4i4IBB6x")
TIMEBASE_KIND = {0: "monotonic", 1: "tai"}
# The module's error bits (docs/registers.md, error bits): a fault- / warning-class bit is set;
# an analogue error holds the last good position (validity stale).
FLAG_FAULT, FLAG_WARNING, FLAG_HELD = 0x08, 0x10, 0x20
_M64 = (1 << 64) - 1


class AbiMismatch(Exception):
    """The object under the name is not ds1928d shared memory of ABI version 1."""


class NotReady(Exception):
    """The daemon is still creating the object (retry shortly)."""


class TornRead(Exception):
    """No consistent copy in the allowed attempts (a writer died in the middle of a record)."""


class DaemonStopped(Exception):
    """wait(): the daemon stopped; its object is no longer updated."""


def check_value(words):
    """ds1928_shm_check() of the first eight payload words."""
    h = 0x6A09E667F3BCC909
    for w in words[:8]:
        h = ((h ^ w) * 0x9E3779B97F4A7C15) & _M64
        h ^= h >> 29
    return h


@dataclass(frozen=True)
class AxisData:
    """One axis record (struct ds1928_axis_data), the names of ds1928ctl --json position."""
    axis: int
    position_raw: int
    periods: int
    fraction: int
    pos_time_ns: int
    publish_ns: int
    cycle: int
    position_sdc: int
    pos_time_raw: int
    endat_error: int
    endat_warning: int
    time_source: str
    pos_cycle: int
    error_info: int
    state: str
    flags: int

    @property
    def valid(self):
        return self.state == "valid"

    @property
    def fresh(self):
        return bool(self.flags & FLAG_FRESH)

    @property
    def new_position(self):
        return bool(self.flags & FLAG_NEW_POSITION)

    @property
    def fault(self):
        return bool(self.flags & FLAG_FAULT)

    @property
    def warning(self):
        return bool(self.flags & FLAG_WARNING)

    @property
    def held(self):
        return bool(self.flags & FLAG_HELD)

    @property
    def position(self):
        """Whole and fractional sine periods as a float."""
        return self.periods + self.fraction / 65536.0

    info: tuple = ()  # InfoChannel per configured channel (a daemon with FEATURE_INFO)


@dataclass(frozen=True)
class InfoChannel:
    """One configured additional-information channel (EnDatInfo0N), as ds1928ctl --json
    position prints it: the last value read with EnDatInfoOK set, whether the last read had it,
    and that value's age (None: never read valid)."""
    channel: int  # 1..4
    name: str
    value: int
    valid: bool
    age_us: Optional[int]


def _shm_path(name):
    if not name.startswith("/") or "/" in name[1:] or len(name) < 2:
        raise ValueError(f"shared memory name {name!r}: one '/' then a file name")
    return "/dev/shm" + name


_libc = None
_SYS_FUTEX = {"x86_64": 202, "aarch64": 98, "armv7l": 240, "i686": 240}.get(os.uname().machine)
_FUTEX_WAIT_BITSET = 9


@dataclass(frozen=True)
class Timebase:
    """The bus's time base (header fields of DS1928_SHM_FEATURE_TIMEBASE): cycle n starts at
    t0_ns + n * period_ns on CLOCK_MONOTONIC; the publication follows the start by
    publish_offset_p50_ns / _p99_ns / _max_ns (last measurement window, 0 = not yet)."""
    t0_ns: int
    period_ns: int
    publish_offset_p50_ns: int
    publish_offset_p99_ns: int
    publish_offset_max_ns: int
    kind: str
    tai_offset_ns: int
    steps: int
    last_step_ns: int


@dataclass(frozen=True)
class Sample:
    """One pass of Reader.cycles(): the cycle it was timed for, when it woke (CLOCK_MONOTONIC
    ns), the predicted publication, and every axis as read then."""
    cycle: int
    publication_ns: int
    woke_ns: int
    axes: list


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class Reader:
    """A mapped daemon instance: Reader(name="/ds1928d")."""

    def __init__(self, name=DEFAULT_NAME, open_wait=True):
        self.name = name
        self._map = None
        self._wait = None
        self._open(open_wait)

    # -- mapping ---------------------------------------------------------------------------
    def _open(self, open_wait):
        path = _shm_path(self.name)
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOFOLLOW)
        except FileNotFoundError:
            raise FileNotFoundError(errno.ENOENT, f"no shared memory {self.name} (is ds1928d "
                                    "running?)", path) from None
        try:
            st = os.fstat(fd)
            import stat as _stat
            if not _stat.S_ISREG(st.st_mode):
                raise AbiMismatch(f"{self.name}: not a regular file")
            if st.st_size < HEADER_SIZE:
                raise NotReady(f"{self.name}: being created")
            m = mmap.mmap(fd, st.st_size, mmap.MAP_SHARED, mmap.PROT_READ)
        finally:
            os.close(fd)
        u64 = memoryview(m).cast("Q")
        magic = u64[0]
        if magic == 0:
            u64.release()
            m.close()
            raise NotReady(f"{self.name}: being created")
        (magic, abi, header_size, record_size, axis_count, generation, period,
         pid) = _HEADER_CONST.unpack_from(m, 0)
        problem = None
        if magic != SHM_MAGIC:
            problem = f"magic {magic:#018x}, expected {SHM_MAGIC:#018x} (not ds1928d shared memory)"
        elif abi != ABI_VERSION:
            problem = f"ABI version {abi}, this reader knows version {ABI_VERSION}"
        elif header_size < HEADER_SIZE or record_size < RECORD_SIZE or \
                header_size + axis_count * record_size > st.st_size:
            problem = (f"header_size {header_size}, record_size {record_size}, {axis_count} axes "
                       f"do not fit ABI version {ABI_VERSION} in {st.st_size} bytes")
        if problem:
            u64.release()
            m.close()
            raise AbiMismatch(f"{self.name}: {problem}")
        self._map, self._u64, self._u32 = m, u64, memoryview(m).cast("I")
        self.header_size, self.record_size = header_size, record_size
        self.axis_count, self.generation = axis_count, generation
        self.cycle_period_ns, self.daemon_pid = period, pid
        if open_wait:
            self._open_wait()

    def _open_wait(self):
        try:
            fd = os.open(_shm_path(self.name + WAIT_SUFFIX), os.O_RDWR | os.O_CLOEXEC | os.O_NOFOLLOW)
        except OSError:
            return  # no write permission: reading still works, wait() does not
        try:
            w = mmap.mmap(fd, WAIT_SIZE, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)
        except (OSError, ValueError):
            return
        finally:
            os.close(fd)
        magic, generation = struct.unpack_from("<QQ", w, 0)
        if magic != WAIT_MAGIC or generation != self.generation:
            w.close()
            return
        self._wait = w

    def close(self):
        for attr in ("_u64", "_u32"):
            view = getattr(self, attr, None)
            if view is not None:
                view.release()
                setattr(self, attr, None)
        if self._map is not None:
            self._map.close()
            self._map = None
        if self._wait is not None:
            self._wait.close()
            self._wait = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def reopen(self):
        """For a reader whose daemon stopped or died: True when a new generation is now mapped."""
        try:
            fresh = Reader(self.name, open_wait=True)
        except (OSError, NotReady):
            return False
        if fresh.generation == self.generation:
            fresh.close()
            return False
        self.close()
        self.__dict__.update(fresh.__dict__)
        fresh.__dict__.clear()
        return True

    # -- header ----------------------------------------------------------------------------
    @property
    def state(self):
        return STATE.get(self._u32[64 // 4], "unknown")

    @property
    def last_cycle(self):
        return self._u64[72 // 8]

    @property
    def last_publish_ns(self):
        return self._u64[80 // 8]

    @property
    def publish_count(self):
        return self._u64[88 // 8]

    @property
    def features(self):
        return self._u32[44 // 4]

    @property
    def has_timebase(self):
        return bool(self.features & FEATURE_TIMEBASE)

    @property
    def has_info(self):
        return bool(self.features & FEATURE_INFO)

    def info_name(self, axis, channel):
        """The name of channel `channel` (0-based) of `axis` (axes[].info), or None."""
        if not self.has_info or not 0 <= axis < self.axis_count or \
                not 0 <= channel < INFO_CHANNELS:
            return None
        offset = self._u32[120 // 4]
        at = offset + (axis * INFO_CHANNELS + channel) * INFO_NAME_LEN
        if offset == 0 or at + INFO_NAME_LEN > len(self._map):
            return None
        raw = bytes(self._map[at:at + INFO_NAME_LEN])
        if raw[0] == 0 or b"\0" not in raw:
            return None
        return raw.split(b"\0", 1)[0].decode("utf-8", "replace")

    def timebase(self):
        """The time base, or None when the daemon publishes none (an older daemon)."""
        if not self.has_timebase:
            return None
        t0, tai = struct.unpack("<qq", self._u64[6:8].tobytes())
        p50, p99, pmax, kind = self._u32[96 // 4:112 // 4].tolist()
        (last_step,) = struct.unpack("<q", self._u64[14:15].tobytes())
        return Timebase(t0_ns=t0, period_ns=self.cycle_period_ns, publish_offset_p50_ns=p50,
                        publish_offset_p99_ns=p99, publish_offset_max_ns=pmax,
                        kind=TIMEBASE_KIND.get(kind, "unknown"), tai_offset_ns=tai,
                        steps=self._u32[68 // 4], last_step_ns=last_step)

    def next_publication(self, after_ns=None, every=1):
        """As ds1928_shm_next_publication(): (at_ns, cycle) of the first publication after
        `after_ns` (default: now) whose cycle is a multiple of `every`: that cycle's start plus
        the measured publication offset p99. None while there is no time base (an older daemon,
        or before the first cycle)."""
        if not self.has_timebase:
            return None
        t0 = struct.unpack("<q", self._u64[6:7].tobytes())[0]
        period = self.cycle_period_ns
        if t0 == 0 or period <= 0:
            return None
        offset = self._u32[100 // 4]
        if after_ns is None:
            after_ns = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
        step = period * max(1, int(every))
        rel = after_ns - offset - t0
        k = 0 if rel < 0 else rel // step + 1
        return t0 + k * step + offset, k * max(1, int(every))

    def cycles(self, every=1, offset_us=0, timeout=1.0):
        """Isochronous loop: yields a Sample at every `every`-th publication, `offset_us` after
        its predicted instant (next_publication()), woken by clock_nanosleep(TIMER_ABSTIME) on
        CLOCK_MONOTONIC: no wake-up from the daemon. A pass that woke a whole step late skips to
        the next one ahead (never a burst). Without a time base it falls back to wait(); raises
        DaemonStopped when the daemon stops and TimeoutError when it publishes nothing for
        `timeout` seconds."""
        every = max(1, int(every))
        offset_ns = int(offset_us * 1000)
        after = None
        last = None
        while True:
            nxt = self.next_publication(after, every)
            if nxt is None:
                seen = self.wait(None, every, timeout)
                if seen is None:
                    raise TimeoutError(f"{self.name}: no publication for {timeout} s")
                now = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
                yield Sample(cycle=seen, publication_ns=self.last_publish_ns, woke_ns=now,
                             axes=self.axes())
                continue
            at, cycle = nxt
            if last is not None and cycle <= last:
                # The measured offset grew since the last pass: the same cycle again. Next one.
                at, cycle = at + (last + every - cycle) * self.cycle_period_ns, last + every
            last = cycle
            _sleep_until(at + offset_ns)
            woke = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
            if self.state == "stopped":
                raise DaemonStopped(f"{self.name}: the daemon stopped")
            if not self.daemon_alive(max(10, int(timeout * 1e9) // max(1, self.cycle_period_ns))):
                raise TimeoutError(f"{self.name}: no publication for {timeout} s")
            yield Sample(cycle=cycle, publication_ns=at, woke_ns=woke, axes=self.axes())
            # Late by a whole step or more (a stop in the debugger, a stalled process): resume
            # at the first publication ahead instead of catching up.
            after = at if woke - at < self.cycle_period_ns * every else woke

    def acq_to_publish(self, axis=0):
        """(this cycle's, the last window's largest) time from the axis' acquisition to the
        publication, in ns; (0, 0) without a time base or a stamped input."""
        if not 0 <= axis < self.axis_count:
            raise IndexError(f"axis {axis}: the daemon has {self.axis_count} axes")
        if not self.has_timebase:
            return (0, 0)
        i = (self.header_size + axis * self.record_size + 80) // 4
        return (self._u32[i], self._u32[i + 1])

    def daemon_alive(self, missed_cycles=10):
        """As ds1928_shm_daemon_alive(): not stopped and published within max(N periods, 100 ms)."""
        if self.state == "stopped":
            return False
        last = self.last_publish_ns
        if last == 0:
            return True
        tolerance = max(self.cycle_period_ns * missed_cycles, 100_000_000)
        return time.clock_gettime_ns(time.CLOCK_MONOTONIC) - last <= tolerance

    # -- records ---------------------------------------------------------------------------
    def words(self, axis, attempts=100_000, info=False):
        """The nine payload words of one consistent copy (seqlock + check word); with
        info=True a pair (payload words, the channels' five words) from the same copy."""
        if not 0 <= axis < self.axis_count:
            raise IndexError(f"axis {axis}: the daemon has {self.axis_count} axes")
        u64 = self._u64
        seq_index = (self.header_size + axis * self.record_size) // 8
        first, stop = seq_index + 1, seq_index + 1 + DATA_WORDS
        info_first = seq_index + 11
        for _ in range(attempts):
            s1 = u64[seq_index]
            if s1 & 1:
                continue
            words = u64[first:stop].tolist()
            extra = u64[info_first:info_first + INFO_WORDS].tolist() if info else None
            if u64[seq_index] == s1 and check_value(words) == words[8]:
                return (words, extra) if info else words
        raise TornRead(f"{self.name}: axis {axis} stayed locked for {attempts} attempts")

    def axis(self, axis=0):
        channels = ()
        if self.has_info:
            w, extra = self.words(axis, info=True)
            values = _INFO.unpack(struct.pack(f"<{INFO_WORDS}Q", *extra))
            valid, configured = values[8], values[9]
            channels = tuple(
                InfoChannel(channel=n + 1, name=self.info_name(axis, n) or f"info{n + 1}",
                            value=values[n], valid=bool(valid & (1 << n)),
                            age_us=None if values[4 + n] == INFO_AGE_NEVER else values[4 + n])
                for n in range(INFO_CHANNELS) if configured & (1 << n))
        else:
            w = self.words(axis)
        (raw, periods, pos_time, publish, cycle, sdc, pos_time_raw, endat_error, endat_warning,
         fraction, time_source, pos_cycle, error_info, validity, flags, _reserved,
         _check) = _PAYLOAD.unpack(struct.pack("<9Q", *w))
        return AxisData(axis=axis, position_raw=raw, periods=periods, fraction=fraction,
                        pos_time_ns=pos_time, publish_ns=publish, cycle=cycle, position_sdc=sdc,
                        pos_time_raw=pos_time_raw, endat_error=endat_error,
                        endat_warning=endat_warning,
                        time_source=TIME_SOURCE.get(time_source, "none"), pos_cycle=pos_cycle,
                        error_info=error_info, state=VALIDITY.get(validity, "unknown"),
                        flags=flags, info=channels)

    def axes(self):
        return [self.axis(a) for a in range(self.axis_count)]

    # -- waiting (futex) -------------------------------------------------------------------
    @property
    def can_wait(self):
        return self._wait is not None and _SYS_FUTEX is not None

    def wait_start(self):
        """The starting value of wait()'s `seen`: the last published cycle (None before any)."""
        return self.last_cycle if self.publish_count != 0 else None

    def _due(self, seen, every):
        if self.publish_count == 0:
            return None
        cycle = self.last_cycle
        if seen is None:
            return cycle if cycle % every == 0 else None
        return cycle if cycle > seen and cycle // every > seen // every else None

    def _slot(self, every):
        """The wait slot for `every` (claimed when free), as ds1928_shm_wait_slot_for()."""
        w32 = memoryview(self._wait).cast("I")
        try:
            for factor in ((every, 1) if every != 1 else (1,)):
                for i in range(WAIT_SLOTS):
                    f = w32[(128 + 8 * i) // 4]
                    if f == factor:
                        return i
                    if f == 0 and _cas32(self._wait, 128 + 8 * i, 0, factor) in (0, factor):
                        return i
            return -1
        finally:
            w32.release()

    def wait(self, seen=None, every=1, timeout=1.0):
        """Sleeps until a publication whose cycle is a multiple of `every` follows cycle `seen`
        (None: the next matching one). Returns the last published cycle, or None on timeout;
        raises DaemonStopped when the daemon stops. Without write access to <name>.wait (or on
        an architecture without a known futex number) it polls at the bus period."""
        every = max(1, int(every))
        if seen is None:
            seen = self.wait_start()
        deadline = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + int(timeout * 1e9)
        slot = self._slot(every) if self.can_wait else -1
        while True:
            if slot >= 0:
                _atomic_add32(self._wait, 128 + 8 * slot + 4, 1)
            try:
                futex_value = struct.unpack_from("<I", self._wait, 64)[0] if slot >= 0 else 0
                cycle = self._due(seen, every)
                if cycle is not None:
                    return cycle
                if self.state == "stopped":
                    raise DaemonStopped(f"{self.name}: the daemon stopped")
                now = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
                if now >= deadline:
                    return None
                if slot >= 0:
                    _futex_wait(self._wait, 64, futex_value, deadline, 1 << slot)
                else:
                    time.sleep(min(max(self.cycle_period_ns, 100_000), deadline - now) / 1e9)
            finally:
                if slot >= 0:
                    _atomic_add32(self._wait, 128 + 8 * slot + 4, -1)


# ---- atomics and the futex through ctypes ------------------------------------------------------
# Python has no atomic read-modify-write on a mapping; the registration counters need one (the
# daemon and other readers change them concurrently). libatomic's __atomic_fetch_add_4 and
# __atomic_compare_exchange_4 are the C11 atomics the header uses, reached through ctypes.

def _lib():
    global _libc
    if _libc is None:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        atomic_name = ctypes.util.find_library("atomic") or "libatomic.so.1"
        atomic = ctypes.CDLL(atomic_name)
        atomic.__atomic_fetch_add_4.restype = ctypes.c_uint32
        atomic.__atomic_fetch_add_4.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int]
        atomic.__atomic_compare_exchange_4.restype = ctypes.c_bool
        atomic.__atomic_compare_exchange_4.argtypes = [ctypes.c_void_p, ctypes.c_void_p,
                                                       ctypes.c_uint32, ctypes.c_int, ctypes.c_int]
        libc.syscall.restype = ctypes.c_long
        _libc = (libc, atomic)
    return _libc


def _address(m, offset):
    return ctypes.addressof(ctypes.c_char.from_buffer(m, offset))


_SEQ_CST = 5


def _atomic_add32(m, offset, delta):
    _lib()[1].__atomic_fetch_add_4(_address(m, offset), delta & 0xFFFFFFFF, _SEQ_CST)


def _cas32(m, offset, expected, desired):
    """Compare-and-swap; returns the value seen (== expected on success)."""
    seen = ctypes.c_uint32(expected)
    _lib()[1].__atomic_compare_exchange_4(_address(m, offset), ctypes.byref(seen), desired,
                                          _SEQ_CST, _SEQ_CST)
    return seen.value


def _sleep_until(deadline_ns):
    """clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME): an absolute wake-up, so that a late
    pass never shifts the later ones."""
    libc = _lib()[0]
    ts = _Timespec(deadline_ns // 1_000_000_000, deadline_ns % 1_000_000_000)
    while libc.clock_nanosleep(ctypes.c_int(time.CLOCK_MONOTONIC), ctypes.c_int(1),
                               ctypes.byref(ts), None) == errno.EINTR:
        pass


def _futex_wait(m, offset, value, deadline_ns, bitset):
    libc = _lib()[0]
    ts = _Timespec(deadline_ns // 1_000_000_000, deadline_ns % 1_000_000_000)
    r = libc.syscall(ctypes.c_long(_SYS_FUTEX), ctypes.c_void_p(_address(m, offset)),
                     ctypes.c_int(_FUTEX_WAIT_BITSET), ctypes.c_uint32(value), ctypes.byref(ts),
                     ctypes.c_void_p(0), ctypes.c_uint32(bitset))
    if r != 0:
        e = ctypes.get_errno()
        if e not in (errno.EAGAIN, errno.ETIMEDOUT, errno.EINTR):
            raise OSError(e, os.strerror(e))
