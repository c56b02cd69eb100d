"""The profiler's name parsing (the profile itself needs Linux perf and an idle machine)."""

from path_profile import readable


def test_numba_symbols_read_as_dotted_names() -> None:
    symbol = (
        "_ZN3dpm6tracer8traverse11closest_hitB3v42B46c8tJTIeFIjxB2IKSgI4CrvSCKg1MMbCQQPKkLTj8N"
        "AE_3dE200BVHArrays_28array_28float32_2c_202d_2c_20C_29"
    )
    assert readable(symbol) == "dpm.tracer.traverse.closest_hit"
    assert readable("__sincos_fma") == "__sincos_fma"
    gufunc = "_ZN13_3cdynamic_3e36__numba_parfor_gufunc_0x7f13a0c84cd0B4v227B106c8tJTC"
    assert readable(gufunc) == "_3cdynamic_3e.__numba_parfor_gufunc_0x7f13a0c84cd0"
