"""A per-process cache of decoded input files, for the warm workers of :mod:`mcbench.pipeline.worker_pool`.

A worker runs many small jobs of the same cases: every method of a case reads its render, every
entry of a case its reference, the ensembles the same base outputs. :func:`cached_read` keeps
what a reader returned, keyed by the file's path, its (device, inode, size, mtime and ctime in ns) and
the caller's key, so a file rewritten by a later job (written atomically: a new inode and mtime)
or changed in place (a new ctime, which no one can set back) is read again, never served stale. Arrays handed out are made read-only: a step that wrote into an
input in place would otherwise change what the next job reads, so it fails loudly instead. The
cache holds at most ``MAX_BYTES`` of arrays (least recently used out first); a file larger than
that is read and not kept.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict

import numpy as np

__all__ = ["MAX_BYTES", "cached_read", "clear_cache"]

#: Bytes of decoded arrays a process keeps (the renders, references and outputs of a few cases).
MAX_BYTES = 768 * 2**20

_lock = threading.Lock()
_entries: OrderedDict = OrderedDict()
_sizes: dict = {}
_total = 0


def _arrays(value):
    """Every ndarray reachable in ``value`` (dicts, lists, tuples, objects' ``__dict__``)."""
    if isinstance(value, np.ndarray):
        yield value
    elif isinstance(value, dict):
        for item in value.values():
            yield from _arrays(item)
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _arrays(item)
    elif hasattr(value, "__dict__"):
        for item in vars(value).values():
            yield from _arrays(item)


def cached_read(path: str, reader, *, key=()):
    """``reader(path)``, from the cache when ``path`` is unchanged since it was read with the same ``key``."""
    global _total
    try:
        stat = os.stat(path)
    except OSError:
        return reader(path)                  # the reader's own error names the file
    identity = (os.path.abspath(path), key, stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns,
                stat.st_ctime_ns)
    with _lock:
        if identity in _entries:
            _entries.move_to_end(identity)
            return _entries[identity]
    value = reader(path)
    arrays = list(_arrays(value))
    for array in arrays:
        array.flags.writeable = False
    size = sum(array.nbytes for array in arrays)
    if size > MAX_BYTES:
        return value
    with _lock:
        _entries[identity] = value
        _sizes[identity] = size
        _total += size
        while _total > MAX_BYTES and _entries:
            old, _ = _entries.popitem(last=False)
            _total -= _sizes.pop(old)
    return value


def clear_cache() -> None:
    """Forget every cached file."""
    global _total
    with _lock:
        _entries.clear()
        _sizes.clear()
        _total = 0
