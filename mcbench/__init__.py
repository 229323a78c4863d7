"""Core of the MC-denoiser benchmark harness: EXR I/O, render buffers, rendering,
metrics, ranking and reports. Methods live in ``methods/``, scenes in ``scenes/``."""

__all__ = ["BenchError"]


class BenchError(RuntimeError):
    """An error the user can fix: the message names the offending file or config key."""
