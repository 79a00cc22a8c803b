"""Keep freed memory in the process's heap (glibc), so a learner's per-update tensors reuse pages.

glibc serves a block over its mmap threshold (128 KiB at start, rising to at most 32 MiB) with
fresh pages from ``mmap`` and hands them back to the kernel when the block is freed. A conv learner
allocates the same activation and gradient buffers at every update, so every update page-faults
them in again and the kernel zeroes each page: on a 2-core CPU a pixel DBC process spent about 13%
of its time in the kernel that way. Two ``mallopt`` settings stop it: large blocks come from the
heap like small ones (``M_MMAP_MAX = 0``), and the heap's free top is not trimmed
(``M_TRIM_THRESHOLD`` at its largest). What a run computes is unchanged (torch aligns every block
itself); the process keeps the heap of its peak until it exits. ``bench/malloc_retain.py`` measures it.
"""
from __future__ import annotations

import ctypes
import logging
from collections.abc import Callable

log = logging.getLogger(__name__)

# mallopt's parameter numbers, from glibc's <malloc.h>
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
NEVER_TRIM = 2**31 - 1  # mallopt takes an int: 2 GiB of free heap top before any is handed back


def glibc_mallopt() -> Callable[[int, int], int] | None:
    """The running C library's ``mallopt`` where that library is glibc, else None (macOS has
    none; musl's accepts and ignores every setting)."""
    libc = ctypes.CDLL(None)
    if not hasattr(libc, "gnu_get_libc_version") or not hasattr(libc, "mallopt"):
        return None
    libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    libc.mallopt.restype = ctypes.c_int
    return libc.mallopt


def retain_freed_memory() -> bool:
    """Apply both settings to this process; returns whether glibc took them (False: not glibc,
    nothing changed). Irreversible for the process, as it is meant to be: a runner calls it once."""
    mallopt = glibc_mallopt()
    if mallopt is None:
        log.info("retain_freed_memory: the C library is not glibc, the setting has no effect here")
        return False
    taken = mallopt(M_MMAP_MAX, 0) == 1 and mallopt(M_TRIM_THRESHOLD, NEVER_TRIM) == 1
    if taken:
        log.info("retain_freed_memory: freed memory stays in this process's heap (glibc mallopt)")
    else:
        log.warning("retain_freed_memory: glibc refused the mallopt settings; memory is handled as by default")
    return taken
