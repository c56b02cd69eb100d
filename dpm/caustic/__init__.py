"""`auto`'s learned caustic filter at render time, in NumPy and Numba alone (no JAX).

`stats`: what the filter reads of a render in passes (per-pixel SPPM statistics, scale-free
features, candidate estimates) and the clamp that keeps the render consistent; `forward`: the
network's forward pass and its weight file; `halves`: what each pass gathered alone, summed
in two independent halves of the passes; `blend`: how far the caustic moves towards the
narrow kernel's estimate and the filter's, fitted on those halves (with or without the
network). The Flax network they copy, and its training,
are `dpm.nn.caustic_net` and `dpm.nn.caustic_training`: importing JAX would cost a 2-second
render most of its budget.
"""
