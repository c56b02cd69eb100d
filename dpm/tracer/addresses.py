"""Arrays passed to compiled functions by address: the calls that are not inlined stay cheap.

A Numba function that is not inlined receives each array argument as its whole struct (data,
shape, strides, item size, owner: 9 words for a 2-D array), and a NamedTuple of arrays as all
of its members': a `SceneArrays` is 141 words and a `BVHArrays` 43, pushed on the stack at
every call. Measured on Zen 3 (one thread): the traversal's calls cost 18 ns of a 60-ns ray
that misses everything, and `pt` on the ring spent about a quarter of its time copying the
arguments of the camera's specular chain. A bundle's addresses and shapes (`words`) are
2-4 words an array (`by_address`), and the arrays are made again on the other side.

The arrays must be C-contiguous (checked when the caller is compiled, by `address` and
`by_address`) and stay alive for the call: the views made here own nothing, so each wrapper
ends with `keep_alive` on what it passed.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.core.errors import TypingError
from numba.extending import intrinsic

from dpm.scene import SceneArrays
from dpm.tracer.bvh import BVHArrays


@intrinsic
def address(typingctx, array):
    """The address (int64) of a C-contiguous array's first element."""
    _layout(array)

    def codegen(context, builder, sig, args):
        data = context.make_array(sig.args[0])(context, builder, args[0]).data
        return builder.ptrtoint(data, ir.IntType(64))

    return types.int64(array), codegen


@intrinsic
def keep_alive(typingctx, *values):
    """Nothing, at run time; to Numba, a use of `values` after the call that reads their
    addresses. Numba frees an array after its last use, not at the end of its scope: an array
    made for the call (`new_stack(depth)` as an argument) would be freed before the callee
    used its memory."""

    def codegen(context, builder, sig, args):
        return context.get_dummy_value()

    return types.none(types.StarArgTuple(values)), codegen


def _view(context, builder, array_type, at, dims):
    """LLVM value of a C-contiguous array of `array_type` at int64 `at` with intp dims."""
    array = context.make_array(array_type)(context, builder)
    item = context.get_abi_sizeof(context.get_data_type(array_type.dtype))
    strides, step = [], ir.Constant(ir.IntType(64), item)
    for x in reversed(dims):
        strides.insert(0, step)
        step = builder.mul(step, x)
    data = builder.inttoptr(at, context.get_data_type(array_type.dtype).as_pointer())
    size = ir.Constant(ir.IntType(64), item)
    context.populate_array(
        array, data=data, shape=dims, strides=strides, itemsize=size, meminfo=None
    )
    return array._getvalue()


def array_at(dtype: types.Type, ndim: int):
    """An intrinsic (address, shape tuple) -> the C-contiguous `ndim`-D array of `dtype` there."""
    array_type = types.Array(dtype, ndim, "C")

    @intrinsic
    def view(typingctx, at, shape):
        def codegen(context, builder, sig, args):
            dims = [
                context.cast(builder, x, t, types.intp)
                for x, t in zip(
                    cgutils.unpack_tuple(builder, args[1], ndim), sig.args[1], strict=True
                )
            ]
            return _view(context, builder, array_type, args[0], dims)

        return array_type(at, shape), codegen

    return view


def _layout(bundle_type: types.Type) -> list[types.Array]:
    """The arrays of a (nested) tuple type, depth first, each C-contiguous."""
    if isinstance(bundle_type, types.BaseTuple):
        return [a for t in bundle_type.types for a in _layout(t)]
    if not isinstance(bundle_type, types.Array) or bundle_type.layout != "C":
        raise TypingError(f"passed by address: {bundle_type} is not a C-contiguous array")
    return [bundle_type]


def _flatten(builder, value, value_type) -> list:
    """The LLVM values of the arrays of a (nested) tuple, in `_layout`'s order."""
    if isinstance(value_type, types.BaseTuple):
        return [
            x
            for i, t in enumerate(value_type.types)
            for x in _flatten(builder, builder.extract_value(value, i), t)
        ]
    return [value]


def _rebuild(context, builder, value_type, arrays: list):
    """A (nested) tuple of `value_type` from its arrays (consumed from the front)."""
    if isinstance(value_type, types.BaseTuple):
        parts = [_rebuild(context, builder, t, arrays) for t in value_type.types]
        return context.make_tuple(builder, value_type, parts)
    return arrays.pop(0)


def by_address(example: tuple):
    """Two intrinsics for (nested, named or not) tuples of arrays typed as `example` (of the
    dtypes and dimensions callers pass; its values are not used): `to_words(bundle)`, each
    array's address then its shape as one int64 tuple, and `from_words(words)`, the bundle
    again, its arrays viewing the same memory. A bundle of other dtypes or dimensions, or
    not C-contiguous, fails to compile."""
    bundle_type = nb.typeof(example)
    members = _layout(bundle_type)
    n = sum(1 + a.ndim for a in members)
    words_type = types.UniTuple(types.int64, n)

    @intrinsic
    def to_words(typingctx, bundle):
        given = _layout(bundle)
        if [(a.dtype, a.ndim) for a in given] != [(a.dtype, a.ndim) for a in members]:
            raise TypingError(f"passed by address: {bundle} is not like {bundle_type}")

        def codegen(context, builder, sig, args):
            out = []
            for a, value in zip(given, _flatten(builder, args[0], sig.args[0]), strict=True):
                array = context.make_array(a)(context, builder, value)
                out.append(builder.ptrtoint(array.data, ir.IntType(64)))
                out.extend(cgutils.unpack_tuple(builder, array.shape, a.ndim))
            return context.make_tuple(builder, words_type, out)

        return words_type(bundle), codegen

    @intrinsic
    def from_words(typingctx, packed):
        if packed != words_type:
            raise TypingError(f"expected the {n} words of {bundle_type}, got {packed}")

        def codegen(context, builder, sig, args):
            flat, arrays, k = cgutils.unpack_tuple(builder, args[0], n), [], 0
            for a in members:
                arrays.append(_view(context, builder, a, flat[k], flat[k + 1 : k + 1 + a.ndim]))
                k += 1 + a.ndim
            return _rebuild(context, builder, bundle_type, arrays)

        return bundle_type(packed), codegen

    return to_words, from_words


def example_of(bundle: type, dtypes: dict[str, tuple[type, int]]) -> tuple:
    """A `bundle` NamedTuple of empty arrays of the given (dtype, ndim) per field, for
    `by_address`."""
    return bundle(*(np.zeros((0,) * nd, dt) for dt, nd in (dtypes[f] for f in bundle._fields)))


_F32, _I32, _I64, _F64 = np.float32, np.int32, np.int64, np.float64
scene_words, scene_at = by_address(
    example_of(
        SceneArrays,
        {
            "triangles": (_F32, 3), "normals": (_F32, 2), "areas": (_F32, 1),
            "material": (_I32, 1), "kind": (_I32, 1), "albedo": (_F32, 2),
            "specular": (_F32, 2), "emission": (_F32, 2), "ior": (_F32, 1),
            "transmittance": (_F32, 2), "emitter_triangles": (_I32, 1),
            "emitter_cdf": (_F64, 1), "emitter_pdf": (_F64, 1), "uvs": (_F32, 3),
            "texture": (_I32, 1), "texels": (_F32, 2), "texture_dims": (_I64, 2),
        },
    )
)  # fmt: skip
bvh_words, bvh_at = by_address(
    example_of(
        BVHArrays,
        {"bounds": (_F32, 2), "kids": (_I32, 2), "tri_verts": (_F32, 2),
         "tri_index": (_I32, 1), "tri_planes": (_F32, 2)},
    )
)  # fmt: skip
stack_at = array_at(types.int64, 2)


@intrinsic
def stack_words(typingctx, stack):
    """(address, rows) of a traversal stack (`new_stack`: int64 rows of 2, C-contiguous),
    for `stack_at`; another array does not compile."""
    if stack != types.Array(types.int64, 2, "C"):
        raise TypingError(f"a traversal stack is a C-contiguous 2-D int64 array, not {stack}")

    def codegen(context, builder, sig, args):
        array = context.make_array(stack)(context, builder, args[0])
        rows = cgutils.unpack_tuple(builder, array.shape, 2)[0]
        at = builder.ptrtoint(array.data, ir.IntType(64))
        return context.make_tuple(builder, sig.return_type, [at, rows])

    return types.UniTuple(types.int64, 2)(stack), codegen
