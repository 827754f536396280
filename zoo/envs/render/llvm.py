"""Two things the kernel needs from LLVM that numba does not offer: a fused multiply-add and
512-bit vectors.

``fma`` rounds a * b + c once, as XLA's CPU code does wherever LLVM contracted its multiply
and add (numba itself never contracts, so every other product is rounded on its own).

``wide_vectors()`` marks the function that calls it "prefer-vector-width"="512". On CPUs with
AVX-512, LLVM's tuning otherwise vectorises with 256-bit registers, and the kernel's loops
(the night static most) run faster with 512. Elsewhere LLVM ignores it.
Call it first in every function with a hot loop, and in the callers they may be inlined into.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

_WIDE = '"prefer-vector-width"="512"'


@intrinsic
def fma(typingctx, a, b, c):
    """float32 a * b + c rounded once (llvm.fma.f32: one instruction with FMA3)."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(f32, [f32] * 3), "llvm.fma.f32"
        )
        return builder.call(fn, args)

    return sig, codegen


@intrinsic
def wide_vectors(typingctx):
    """Let LLVM vectorise the calling function with 512-bit registers (see the module doc)."""

    def codegen(context, builder, signature, args):
        # llvmlite only accepts the attributes it knows; a string attribute is printed as is
        set.add(builder.function.attributes, _WIDE)
        return context.get_dummy_value()

    return types.void(), codegen
