"""Checking dpm against answers it did not compute itself.

- `dpm.validation.mitsuba`: a dpm scene and camera as a Mitsuba 3 scene (the independent
  renderer the tests and benchmarks compare against), and a side-by-side render
  (`python -m dpm.validation.mitsuba SCENE.obj -o out.png`). Mitsuba 3 is a test extra: it is
  imported only when a function needs it.
- `dpm.validation.luxcore`: a dpm scene and camera as a LuxCoreRender scene (PATHCPU with
  its PhotonGI caustic cache, the second peer of the equal-time benchmarks), rendered in a
  child process (pyluxcore's allocator cannot share a process with SciPy, Numba or
  Mitsuba); `python -m dpm.validation.luxcore SCENE.obj --time T -o out.npy` is a
  time-boxed whole-process run. pyluxcore is a bench extra.
- `dpm.validation.noise`: comparing two renderers' images within their own noise, each
  measured from two independent renders.

Nothing in the renderer imports this package.
"""
