"""Results of the fit's pure numerical functions kept by the content of their inputs.

A fit and a diagnosis of one recording build the same filtered columns, whitening filters
and friction regressors many times over: each plant tried, each scan of a family and the
final checks start from the same samples. :class:`ContentCache` keeps the latest results,
keyed by a SHA-256 digest of the inputs' bytes, shapes and dtypes (never by object
identity: a new array of the same values finds the result, a changed one never does), up
to a memory bound, least recently used first out. Hashing costs a tenth of what a
zero-phase filter of the same array does.

Arrays kept here are private, read-only copies; :meth:`ContentCache.array` hands every
caller an array of its own, so a caller may change what it gets.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def content_key(*parts: Any) -> bytes:
    """SHA-256 digest of ``parts``: arrays by dtype, shape and bytes; anything else by its
    ``repr`` (numbers, strings, tuples of them)."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"<{a.dtype.str}{a.shape}>".encode())
            h.update(a.data)
        else:
            h.update(f"({p!r})".encode())
    return h.digest()


class ContentCache:
    """A least-recently-used store of arrays of at most ``max_bytes`` in all (thread-safe;
    a result is computed outside the lock, so two threads may both compute it once)."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = int(max_bytes)
        self._items: OrderedDict[bytes, FloatArray] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def array(self, key: bytes, compute: Callable[[], FloatArray]) -> FloatArray:
        """The array kept under ``key`` (a copy), else ``compute()``'s, kept for next time."""
        with self._lock:
            kept = self._items.get(key)
            if kept is not None:
                self._items.move_to_end(key)
                self.hits += 1
                return kept.copy()
            self.misses += 1
        out = compute()
        self._keep(key, out)
        return out

    def _keep(self, key: bytes, out: FloatArray) -> None:
        if out.nbytes > self.max_bytes:
            return
        kept = np.array(out, copy=True)
        kept.flags.writeable = False
        with self._lock:
            if key in self._items:
                return
            self._items[key] = kept
            self._bytes += kept.nbytes
            while self._bytes > self.max_bytes:
                _, old = self._items.popitem(last=False)
                self._bytes -= old.nbytes

    def clear(self) -> None:
        """Forget everything (tests; a caller short of memory)."""
        with self._lock:
            self._items.clear()
            self._bytes = 0

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return self._bytes


__all__ = ["ContentCache", "content_key"]
