"""Layer ``io``: files in and out, and the in-memory form of a case's buffers.

* :mod:`mcbench.io.exr` -- multi-layer OpenEXR read/write (atomic), finiteness checks;
* :mod:`mcbench.io.buffers` -- render buffers (full image, half buffers A and B, variances,
  features) and denoised outputs, the layer names and their conventions;
* :mod:`mcbench.io.tables` -- atomic writers of CSV/Markdown/JSON tables and records;
* :mod:`mcbench.io.weights` -- where the learned methods' weights live and loading them safely.
"""
