"""Results of the fit's pure numerical functions kept by the content of their inputs.

A fit and a diagnosis of one recording build the same filtered columns, whitening filters
and friction regressors many times over: each plant tried, each scan of a family and the
final checks start from the same samples. :class:`ContentCache` keeps the latest results,
keyed by a SHA-256 digest of the inputs' bytes, shapes and dtypes (never by object
identity: a new array of the same values finds the result, a changed one never does), up
to a memory bound, least recently used first out. Hashing costs a tenth of what a
zero-phase filter of the same array does.

Arrays kept here are private, read-only copies; :meth:`ContentCache.array` hands every
caller an array of its own, so a caller may change what it gets. :meth:`ContentCache.shared`
hands out the kept object itself, for values nobody can change (the speed prior).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
T = TypeVar("T")


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


def read_only(a: np.ndarray) -> bool:
    """True when ``a`` and every array its memory belongs to are read-only (so its content
    cannot change through any of them, unless someone sets ``writeable`` back on the
    owner: arrays made read-only here are never written again)."""
    base: object = a
    while isinstance(base, np.ndarray):
        if base.flags.writeable:
            return False
        base = base.base
    return base is None or isinstance(base, bytes)


class ContentCache:
    """A least-recently-used store of at most ``max_bytes`` in all, and at most
    ``max_items`` entries when given (thread-safe; a result is computed outside the lock,
    so two threads may both compute it once)."""

    def __init__(self, max_bytes: int, max_items: int | None = None) -> None:
        self.max_bytes = int(max_bytes)
        self.max_items = max_items
        self._items: OrderedDict[bytes, tuple[Any, int]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def array(self, key: bytes, compute: Callable[[], FloatArray]) -> FloatArray:
        """The array kept under ``key`` (a copy), else ``compute()``'s, kept for next time."""
        kept = self._get(key)
        if kept is not None:
            return np.array(kept, copy=True)
        out = compute()
        if out.nbytes <= self.max_bytes:
            private = np.array(out, copy=True)
            private.flags.writeable = False
            self._put(key, private, private.nbytes)
        return out

    def shared(self, key: bytes, compute: Callable[[], T], nbytes: Callable[[T], int]) -> T:
        """The object kept under ``key`` itself, else ``compute()``'s, kept for next time:
        for values nobody can change (frozen, their arrays read-only)."""
        kept = self._get(key)
        if kept is not None:
            return cast(T, kept)
        out = compute()
        self._put(key, out, nbytes(out))
        return out

    def _get(self, key: bytes) -> Any:
        with self._lock:
            hit = self._items.get(key)
            if hit is None:
                self.misses += 1
                return None
            self._items.move_to_end(key)
            self.hits += 1
            return hit[0]

    def _put(self, key: bytes, value: Any, size: int) -> None:
        if size > self.max_bytes:
            return
        with self._lock:
            if key in self._items:
                return
            self._items[key] = (value, size)
            self._bytes += size
            while self._bytes > self.max_bytes or (
                    self.max_items is not None and len(self._items) > self.max_items):
                _, (_, gone) = self._items.popitem(last=False)
                self._bytes -= gone

    def clear(self) -> None:
        """Forget everything (tests; a caller short of memory)."""
        with self._lock:
            self._items.clear()
            self._bytes = 0

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return self._bytes


__all__ = ["ContentCache", "content_key", "read_only"]
