"""`auto`'s learned caustic filter at render time, in NumPy and Numba alone (no JAX).

`stats`: what the filter reads of a render in passes (per-pixel SPPM statistics, scale-free
features, candidate estimates) and the clamp that keeps the render consistent; `forward`: the
network's forward pass and its weight file; `halves`: what each pass gathered alone, summed
in two independent halves of the passes, by which the render judges how much of the
filter's move to keep. The Flax network they copy, and its training,
are `dpm.nn.caustic_net` and `dpm.nn.caustic_training`: importing JAX would cost a 2-second
render most of its budget.
"""
