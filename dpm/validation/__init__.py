"""Checking dpm against answers it did not compute itself.

- `dpm.validation.mitsuba`: a dpm scene and camera as a Mitsuba 3 scene (the independent
  renderer the tests and benchmarks compare against), and a side-by-side render
  (`python -m dpm.validation.mitsuba SCENE.obj -o out.png`). Mitsuba 3 is a test extra: it is
  imported only when a function needs it.
- `dpm.validation.noise`: comparing two renderers' images within their own noise, each
  measured from two independent renders.

Nothing in the renderer imports this package.
"""
