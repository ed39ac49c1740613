"""ds1928: read the positions ds1928d publishes in shared memory, and talk to its control socket.

Pure Python (mmap + struct on the ABI of include/ds1928/shm.h, docs/shared-memory.md):

    >>> import ds1928
    >>> r = ds1928.Reader("/ds1928d")
    >>> r.axis(0)            # one consistent record (seqlock + check word)
    >>> r.wait(every=1)      # sleep until the next publication (futex, through ctypes)
    >>> for s in r.cycles(every=2, offset_us=50):   # isochronous: clock_nanosleep to the
    ...     use(s.axes)                               # publication + 50 µs, every 2nd cycle
    >>> ds1928.Control().status()
"""
from .shm import (ABI_VERSION, AbiMismatch, AxisData, DaemonStopped, InfoChannel, NotReady,
                  Reader, Sample, Timebase, TornRead, check_value)
from .control import Control, ControlError, DaemonUnreachable

__all__ = ["ABI_VERSION", "AbiMismatch", "AxisData", "Control", "ControlError", "DaemonStopped",
           "DaemonUnreachable", "InfoChannel", "NotReady", "Reader", "Sample", "Timebase", "TornRead", "check_value"]
__version__ = "0.1.0"
