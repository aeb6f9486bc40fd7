"""LLVM one-liners the spiking kernels need and numba does not offer: a uint64's bits as a float64,
the count of trailing zero bits (to walk a word's set bits without a branch per bit), a select
that stays a select, and a prefetch hint."""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["bits_to_f64", "prefetch", "select", "trailing_zeros"]


@intrinsic
def bits_to_f64(typingctx, x):  # type: ignore[no-untyped-def]  # noqa: ARG001 — numba intrinsic signature
    """Reinterpret a uint64 as the float64 with the same bits."""

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]  # noqa: ARG001
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.uint64), codegen


@intrinsic
def trailing_zeros(typingctx, x):  # type: ignore[no-untyped-def]  # noqa: ARG001 — numba intrinsic signature
    """The number of trailing zero bits of a nonzero uint64 (one ``tzcnt`` instruction)."""

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]  # noqa: ARG001
        i64 = ir.IntType(64)
        try:
            fn = builder.module.get_global("llvm.cttz.i64")
        except KeyError:
            fn = ir.Function(builder.module, ir.FunctionType(i64, [i64, ir.IntType(1)]), "llvm.cttz.i64")
        return builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 1)])

    return types.uint64(types.uint64), codegen


@intrinsic
def select(typingctx, cond, a, b):  # type: ignore[no-untyped-def]  # noqa: ARG001 — numba intrinsic signature
    """``a if cond else b`` as one LLVM ``select`` of two values already computed.

    numba lowers ``a if cond else b`` to branches; in a vectorised loop LLVM then computes ``a`` only
    where ``cond`` holds, with masked loads and stores (``vmaskmovpd``), which cost 3x the whole
    update on AMD Zen. ``a`` and ``b`` must have one type.
    """

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]  # noqa: ARG001
        return builder.select(args[0], args[1], args[2])

    return a(types.boolean, a, a), codegen


@intrinsic
def prefetch(typingctx, a, i, j):  # type: ignore[no-untyped-def]  # noqa: ARG001 — numba intrinsic signature
    """Hint the cache to fetch the line of 2-D array ``a``'s element ``[i, j]`` (no bounds check,
    no effect on results: a prefetch never faults). For strided reads the hardware prefetchers miss,
    e.g. one tile of a row, then the same tile a whole row (a page or more) further on."""

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        arrty = signature.args[0]
        ary = context.make_array(arrty)(context, builder, value=args[0])
        ptr = cgutils.get_item_pointer(context, builder, arrty, ary, [args[1], args[2]], wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        try:
            fn = builder.module.get_global("llvm.prefetch.p0i8")
        except KeyError:
            fn = ir.Function(
                builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]), "llvm.prefetch.p0i8"
            )
        # read, high temporal locality (keep in all levels), data cache
        builder.call(
            fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)]
        )
        return context.get_dummy_value()

    if not (isinstance(a, types.Array) and a.ndim == 2):
        return None
    return types.void(a, types.intp, types.intp), codegen
