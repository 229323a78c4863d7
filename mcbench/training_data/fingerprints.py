"""Scene fingerprints: a hash of a scene dict's structure and parameters.

:func:`training_scene_fingerprint` hashes a training scene so that tests can check that no
training scene equals a test scene (nor another training scene). The hash does not depend on
the process (a traversed Mitsuba transform is hashed through its matrix) nor on the film size.
"""

from __future__ import annotations

import hashlib
import struct

import numpy as np

from mcbench.training_data.generator import random_scene

__all__ = ["FINGERPRINT_SIZE", "scene_fingerprint", "training_scene_fingerprint"]

FINGERPRINT_SIZE = (32, 24)     # film size used by training_scene_fingerprint (film size is
                                # excluded from fingerprints anyway)


def _feed(h, obj, path: str = "") -> None:
    """Feed a canonical serialisation of ``obj`` into hash ``h`` (film size excluded)."""
    import mitsuba as mi

    if isinstance(obj, dict):
        h.update(b"{")
        is_film = obj.get("type") == "hdrfilm"
        for key in sorted(obj):
            if is_film and key in ("width", "height"):
                continue
            h.update(key.encode() + b":")
            _feed(h, obj[key], path + "." + key)
        h.update(b"}")
    elif isinstance(obj, (list, tuple)):
        h.update(b"[")
        for item in obj:
            _feed(h, item, path)
        h.update(b"]")
    elif isinstance(obj, (bool, np.bool_)):
        h.update(b"b1" if obj else b"b0")
    elif isinstance(obj, (int, np.integer)):
        h.update(b"i" + str(int(obj)).encode())
    elif isinstance(obj, (float, np.floating)):
        h.update(b"f" + struct.pack("<d", float(obj)))
    elif isinstance(obj, str):
        h.update(b"s" + obj.encode())
    elif isinstance(obj, np.ndarray):
        _feed_array(h, obj)
    elif hasattr(obj, "matrix") and "Transform" in type(obj).__name__:
        _feed_array(h, np.array(obj.matrix, dtype=np.float64))
    elif isinstance(obj, mi.Bitmap):
        _feed_array(h, np.array(obj))
    elif isinstance(obj, mi.Object):
        h.update(b"O" + type(obj).__name__.encode())
        params = mi.traverse(obj)
        for key in sorted(params.keys()):
            h.update(key.encode() + b"=")
            try:
                value = params[key]
                # np.array() of a Mitsuba transform is not its matrix (it changes run to run)
                _feed_array(h, np.array(value.matrix if hasattr(value, "matrix") else value))
            except Exception:   # a parameter that is no array (or cannot be read)
                h.update(b"?")
    else:
        try:
            _feed_array(h, np.array(obj))
        except Exception:
            h.update(b"r" + type(obj).__name__.encode())


def _feed_array(h, array: np.ndarray) -> None:
    array = np.ascontiguousarray(array)
    h.update(b"a" + str(array.dtype).encode() + str(array.shape).encode())
    h.update(array.tobytes())


def scene_fingerprint(desc: dict) -> str:
    """SHA-256 (hex) of a scene dict's structure and parameters: keys, types, numbers, strings,
    transforms, bitmaps and Mitsuba objects (meshes: all their traversable parameters, BSDF
    included). The film's width and height are left out, so the fingerprint names the scene,
    not the image size."""
    h = hashlib.sha256()
    _feed(h, desc)
    return h.hexdigest()


def training_scene_fingerprint(seed: int) -> str:
    """:func:`scene_fingerprint` of ``random_scene(seed, ...)``."""
    return scene_fingerprint(random_scene(seed, *FINGERPRINT_SIZE))
