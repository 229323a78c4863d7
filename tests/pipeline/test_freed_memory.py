"""mcbench.pipeline.freed_memory: freed memory is reused instead of page-faulted afresh, and a
training gives the same weights either way.

Each check runs in child processes (``mallopt`` changes the whole process). The fault counts are
the kernel's (``getrusage``'s minor faults): a 64 MiB block freed and allocated again costs its
16 384 pages each time under glibc's defaults and none once kept, so the test fails if the
setting did nothing (a wrong ``mallopt`` parameter, a threshold below the block size).
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import textwrap

import pytest

from mcbench.pipeline.freed_memory import keep_freed_memory
from tests.conftest import REPO

glibc_linux = pytest.mark.skipif(not (sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"),
                                 reason="glibc's mallopt on Linux only")

BLOCK_PAGES = (64 << 20) // 4096


def _child(code: str) -> dict:
    """Run ``code`` (which prints one JSON line last) in a fresh interpreter at the repository root."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=REPO, capture_output=True,
                          text=True, timeout=600, env=None)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


FAULTS = """
    import ctypes, json, resource, sys
    from mcbench.pipeline.freed_memory import keep_freed_memory
    kept = keep_freed_memory() if {keep} else False
    libc = ctypes.CDLL("libc.so.6")
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    size = 64 << 20                                 # above glibc's largest dynamic mmap threshold

    def touch_and_free():
        block = libc.malloc(size)
        ctypes.memset(block, 1, size)
        libc.free(block)

    touch_and_free()                                # first touch: faults either way
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(8):
        touch_and_free()                            # freed and allocated again
    print(json.dumps({{"kept": kept, "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}}))
"""


@glibc_linux
def test_a_freed_block_is_reused_without_page_faults():
    kept = _child(FAULTS.format(keep=True))
    default = _child(FAULTS.format(keep=False))
    assert kept["kept"] is True
    assert default["faults"] >= 8 * BLOCK_PAGES * 0.9     # glibc's default: every block mapped afresh
    assert kept["faults"] < BLOCK_PAGES / 4               # kept: the same pages again


TRAIN = """
    import hashlib, json, tempfile
    from pathlib import Path
    import torch
    if {keep}:
        from mcbench.pipeline.freed_memory import keep_freed_memory
        assert keep_freed_memory()
    from mcbench.nn.train import train_network
    from tests.nn.test_nn import write_crops
    import methods.kpcn as module
    folder = Path(tempfile.mkdtemp())
    crops = write_crops(folder, size=48, crops_per_scene=1)
    train_network(module, crops, folder / "w.pt", folder / "w.json", folder / "c.pt",
                  {{"steps": 3, "batch_size": 2, "patch": 48, "validate_every": 3, "checkpoint_every": 3,
                   "threads": 1, "seed": 1}}, log=lambda m: None)
    state = torch.load(folder / "w.pt", weights_only=True)["state_dict"]
    digest = hashlib.sha256(b"".join(value.numpy().tobytes() for _, value in sorted(state.items())))
    print(json.dumps({{"weights": digest.hexdigest()}}))
"""


@glibc_linux
def test_training_gives_the_same_weights_with_freed_memory_kept():
    kept = _child(TRAIN.format(keep=True))
    default = _child(TRAIN.format(keep=False))
    assert kept["weights"] == default["weights"]


@pytest.mark.parametrize("value", [0, -1, 2 ** 31, True, 1.5])
def test_an_invalid_size_is_refused(value):
    with pytest.raises(ValueError, match="keep_bytes"):
        keep_freed_memory(value)
