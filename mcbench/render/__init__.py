"""Layer ``render``: Mitsuba 3 rendering of noisy buffers and references.

* :mod:`mcbench.render.renderer` -- the wrapped integrator, noisy buffers and reference chunks;
* :mod:`mcbench.render.seeds` -- every 32-bit seed the harness uses;
* :mod:`mcbench.render.geometry` and :mod:`mcbench.render.curves` -- building blocks of
  Python-built scene dicts (meshes, hair curves);
* :mod:`mcbench.render.variants` -- which Mitsuba variant renders, and its thread pool.
"""
