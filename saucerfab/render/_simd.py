"""Small numba building blocks that keep the rasterizer's inner loops vectorized.

numba's ``math.exp`` becomes a call into libm, which stops LLVM from
vectorizing the loop around it unless Intel's SVML is installed (it is not
part of saucerfab's dependencies). :func:`vexp` is an exponential built from
arithmetic, a float->int conversion and a bit cast only, so LLVM turns it into
AVX/NEON code. It takes non-positive arguments (all the rasterizer needs) and
returns 0 below the smallest normal result, so it never makes denormals.

:func:`ftz_on` / :func:`ftz_restore` set and restore the x86 MXCSR
flush-to-zero and denormals-are-zero bits of the calling thread (no-ops on
other CPUs): tiny products such as ``prod (1 - D)`` deep inside many faces
would otherwise fall into denormals, which cost about a hundred cycles each.

:func:`copy8`, :func:`fill8`, :func:`blend8`, :func:`nonzero_mask8` and
:func:`sum8` move, fill, merge, test and sum exactly 8 contiguous elements as
one LLVM vector (unaligned loads and stores): the kernels pack short pixel
runs with them, where a loop would cost LLVM's run-time overlap and length
checks per run (numba runs no SLP vectorizer to merge written-out copies).
They do no bounds checking; the callers keep every 8-lane run inside its
array (padding).
"""

from __future__ import annotations

import platform

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

_X86 = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686")

#: MXCSR bits: FTZ (bit 15) and DAZ (bit 6)
_FTZ_DAZ = np.uint32(0x8040)


def _bits_to_float(bits: int):  # type: ignore[no-untyped-def]
    """An intrinsic that reinterprets an integer as the float of ``bits`` (32 or 64) bits
    (LLVM ``bitcast``), after truncating or sign-extending it to that width."""
    float_type = {32: types.float32, 64: types.float64}[bits]
    ir_float = {32: ir.FloatType(), 64: ir.DoubleType()}[bits]

    def bits_to_float(typingctx, x):  # type: ignore[no-untyped-def]
        if not isinstance(x, types.Integer):
            return None

        def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
            v = args[0]
            if x.bitwidth > bits:
                v = builder.trunc(v, ir.IntType(bits))
            elif x.bitwidth < bits:
                v = builder.sext(v, ir.IntType(bits))
            return builder.bitcast(v, ir_float)

        return float_type(x), codegen

    bits_to_float.__name__ = bits_to_float.__qualname__ = f"_bits_to_f{bits}"
    return intrinsic(bits_to_float)


_bits_to_f32 = _bits_to_float(32)
_bits_to_f64 = _bits_to_float(64)


def _mxcsr_op(builder, name: str, slot):  # type: ignore[no-untyped-def]
    """Emit ``llvm.x86.sse.{st,ld}mxcsr`` (``name``) on the 32-bit stack ``slot``."""
    fnty = ir.FunctionType(ir.VoidType(), [slot.type])
    builder.call(cgutils.get_or_insert_function(builder.module, fnty, name), [slot])


@intrinsic
def _read_mxcsr(typingctx):  # type: ignore[no-untyped-def]
    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        slot = cgutils.alloca_once(builder, ir.IntType(32))
        _mxcsr_op(builder, "llvm.x86.sse.stmxcsr", slot)
        return builder.load(slot)

    return types.uint32(), codegen


@intrinsic
def _write_mxcsr(typingctx, value):  # type: ignore[no-untyped-def]
    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        slot = cgutils.alloca_once(builder, ir.IntType(32))
        builder.store(args[0], slot)
        _mxcsr_op(builder, "llvm.x86.sse.ldmxcsr", slot)
        return context.get_dummy_value()

    return types.void(types.uint32), codegen


if _X86:

    @njit(inline="always")
    def ftz_on() -> np.uint32:
        """Set FTZ/DAZ on this thread; returns the previous MXCSR for :func:`ftz_restore`."""
        old = _read_mxcsr()
        _write_mxcsr(old | _FTZ_DAZ)
        return old

    @njit(inline="always")
    def ftz_restore(old: np.uint32) -> None:
        """Put back the MXCSR that :func:`ftz_on` returned."""
        _write_mxcsr(old)

else:  # other CPUs: denormals stay (correct, only slower)

    @njit(inline="always")
    def ftz_on() -> np.uint32:
        return np.uint32(0)

    @njit(inline="always")
    def ftz_restore(old: np.uint32) -> None:
        return None


# --------------------------------------------------------------------------- exp
#
# exp(x) = 2^n exp(r), n = round(x / ln 2), r = x - n ln 2 with ln 2 split in
# two (Cody-Waite) so r is exact to working precision.

# float32: Cephes expf's polynomial (relative error about 1 ulp on |r| <= ln2/2)
_F = np.float32
_LOG2E_32 = _F(1.4426950408889634)
_LN2HI_32 = _F(0.693359375)
_LN2LO_32 = _F(-2.12194440e-4)
_P32 = tuple(_F(v) for v in (1.9875691500e-4, 1.3981999507e-3, 8.3334519073e-3,
                              4.1665795894e-2, 1.6666665459e-1, 5.0000001201e-1))
_LO_32 = _F(-87.3)  # exp(-87.3) = 1.2e-38 > the smallest normal float32 (1.18e-38)
_HALF_32, _ONE_32, _ZERO_32 = _F(0.5), _F(1.0), _F(0.0)

# float64: Taylor series to degree 13 on |r| <= ln2/2 (truncation error < 5e-18)
_D = np.float64
_LOG2E_64 = _D(1.4426950408889634)
_LN2HI_64 = _D(6.93145751953125e-1)
_LN2LO_64 = _D(1.42860682030941723212e-6)
_T64 = tuple(_D(1.0 / np.prod(np.arange(1, k + 1, dtype=np.float64))) for k in range(13, 1, -1))
_LO_64 = _D(-708.0)  # exp(-708) = 3.3e-308 > the smallest normal float64 (2.2e-308)


def vexp(x):  # type: ignore[no-untyped-def]
    """``exp(x)`` for ``x <= 0`` (float32 or float64), vectorizable; 0 below the normal range.

    Relative error: about 1e-7 (float32), 2e-16 (float64). NaN in, garbage out.
    """
    return np.exp(x)


# exp32 and exp64 are written out step by step on purpose: one generic version
# looping over the coefficients (tried) gives the same results alone, but
# inside the rasterizer's kernels LLVM then contracts their multiply-adds
# differently and images and gradients change in the last bit.
@overload(vexp)
def _vexp_impl(x):  # type: ignore[no-untyped-def]
    if x == types.float32:

        def exp32(x):  # type: ignore[no-untyped-def]
            xc = x if x > _LO_32 else _LO_32
            n = np.floor(xc * _LOG2E_32 + _HALF_32)
            r = xc - n * _LN2HI_32
            r = r - n * _LN2LO_32
            p = _P32[0]
            p = p * r + _P32[1]
            p = p * r + _P32[2]
            p = p * r + _P32[3]
            p = p * r + _P32[4]
            p = p * r + _P32[5]
            y = (p * r * r + r) + _ONE_32
            scale = _bits_to_f32((np.int32(n) + np.int32(127)) << np.int32(23))
            return _ZERO_32 if x < _LO_32 else y * scale

        return exp32
    if x == types.float64:

        def exp64(x):  # type: ignore[no-untyped-def]
            xc = x if x > _LO_64 else _LO_64
            n = np.floor(xc * _LOG2E_64 + 0.5)
            r = xc - n * _LN2HI_64
            r = r - n * _LN2LO_64
            p = _T64[0]
            p = p * r + _T64[1]
            p = p * r + _T64[2]
            p = p * r + _T64[3]
            p = p * r + _T64[4]
            p = p * r + _T64[5]
            p = p * r + _T64[6]
            p = p * r + _T64[7]
            p = p * r + _T64[8]
            p = p * r + _T64[9]
            p = p * r + _T64[10]
            p = p * r + _T64[11]
            y = (p * r * r + r) + 1.0
            # int32 first: AVX2 converts doubles to int32 lanes, not to int64
            scale = _bits_to_f64((np.int64(np.int32(n)) + np.int64(1023)) << np.int64(52))
            return 0.0 if x < _LO_64 else y * scale

        return exp64
    return None


# --------------------------------------------------------------------------- 8-lane copies
#
# Copying a short run of floats between arrays in a loop costs LLVM's loop
# vectorizer a run-time overlap check, a trip-count check and a remainder
# loop per copy (numba runs no SLP vectorizer that would merge a written-out
# copy): more than the copy. These move exactly 8 elements as one vector.


def _vec_ptr(context, builder, aryty, ary, offset):  # type: ignore[no-untyped-def]
    """(pointer to element ``offset`` of the array as a pointer to 8 elements, their vector type)."""
    arr = context.make_array(aryty)(context, builder, ary)
    vty = ir.VectorType(context.get_data_type(aryty.dtype), 8)
    return builder.bitcast(builder.gep(arr.data, [offset]), vty.as_pointer()), vty


def _splat(builder, vty, value):  # type: ignore[no-untyped-def]
    """``value`` in every lane of vector type ``vty``."""
    vec = ir.Constant(vty, ir.Undefined)
    for k in range(vty.count):
        vec = builder.insert_element(vec, value, ir.Constant(ir.IntType(32), k))
    return vec


def _lanes_below(builder, n):  # type: ignore[no-untyped-def]
    """An 8-lane i1 mask: lane k set where k < ``n`` (an i64)."""
    i64 = ir.IntType(64)
    lanes = ir.Constant(ir.VectorType(i64, 8), [ir.Constant(i64, k) for k in range(8)])
    return builder.icmp_signed("<", lanes, _splat(builder, ir.VectorType(i64, 8), n))


@intrinsic
def copy8(typingctx, dst, doff, src, soff):  # type: ignore[no-untyped-def]
    """``dst[doff:doff + 8] = src[soff:soff + 8]`` as one unaligned vector load and store.

    ``dst`` and ``src``: contiguous 1-D arrays of one float dtype; ``doff``,
    ``soff``: element offsets. No bounds or negative-index handling: the caller
    keeps both runs inside their arrays.
    """
    if not (isinstance(dst, types.Array) and isinstance(src, types.Array) and dst.dtype == src.dtype
            and dst.ndim == 1 and src.ndim == 1 and dst.layout == "C" and src.layout == "C"):
        return None
    sig = types.void(dst, types.intp, src, types.intp)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        sptr, vty = _vec_ptr(context, builder, sig.args[2], args[2], args[3])
        dptr, _ = _vec_ptr(context, builder, sig.args[0], args[0], args[1])
        builder.store(builder.load(sptr, align=1), dptr, align=1)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def fill8(typingctx, dst, doff, value):  # type: ignore[no-untyped-def]
    """``dst[doff:doff + 8] = value`` as one unaligned vector store (as :func:`copy8`)."""
    if not (isinstance(dst, types.Array) and dst.ndim == 1 and dst.layout == "C" and value == dst.dtype):
        return None
    sig = types.void(dst, types.intp, dst.dtype)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        dptr, vty = _vec_ptr(context, builder, sig.args[0], args[0], args[1])
        builder.store(_splat(builder, vty, args[2]), dptr, align=1)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def blend8(typingctx, dst, doff, src, soff, n):  # type: ignore[no-untyped-def]
    """``dst[doff:doff + m] = src[soff:soff + m]``, ``m = min(n, 8)``: 8 lanes of each
    loaded, the first m taken from ``src``, all 8 stored back (as :func:`copy8`;
    ``dst[doff + m:doff + 8]`` is rewritten with its own values, so no other
    thread may write there meanwhile)."""
    if not (isinstance(dst, types.Array) and isinstance(src, types.Array) and dst.dtype == src.dtype
            and dst.ndim == 1 and src.ndim == 1 and dst.layout == "C" and src.layout == "C"
            and isinstance(n, types.Integer)):
        return None
    sig = types.void(dst, types.intp, src, types.intp, types.intp)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        sptr, vty = _vec_ptr(context, builder, sig.args[2], args[2], args[3])
        dptr, _ = _vec_ptr(context, builder, sig.args[0], args[0], args[1])
        take = _lanes_below(builder, args[4])
        new = builder.load(sptr, align=1)
        old = builder.load(dptr, align=1)
        builder.store(builder.select(take, new, old), dptr, align=1)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def nonzero_mask8(typingctx, src, off, n):  # type: ignore[no-untyped-def]
    """Bit k set where k < min(n, 8) and ``src[off + k] != 0``: one vector compare
    instead of a loop with a branch per lane (as :func:`copy8`: no bounds handling)."""
    if not (isinstance(src, types.Array) and src.ndim == 1 and src.layout == "C"
            and isinstance(src.dtype, types.Float) and isinstance(n, types.Integer)):
        return None
    sig = types.int64(src, types.intp, types.intp)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        sptr, vty = _vec_ptr(context, builder, sig.args[0], args[0], args[1])
        i64 = ir.IntType(64)
        within = _lanes_below(builder, args[2])
        nonzero = builder.fcmp_unordered("!=", builder.load(sptr, align=1), ir.Constant(vty, None))
        return builder.zext(builder.bitcast(builder.and_(within, nonzero), ir.IntType(8)), i64)

    return sig, codegen


#: first and last set bit of each 8-bit mask (32 and -1 for none)
FIRST_BIT = np.array([next((k for k in range(8) if m >> k & 1), 32) for m in range(256)], np.int64)
LAST_BIT = np.array([max((k for k in range(8) if m >> k & 1), default=-1) for m in range(256)], np.int64)


@intrinsic
def sum8(typingctx, src, off):  # type: ignore[no-untyped-def]
    """``src[off:off + 8].sum()`` as a fixed tree of vector adds, ((0+4) + (2+6)) + ((1+5)
    + (3+7)): one load and three adds, the same order every call (as :func:`copy8`: no
    bounds handling)."""
    if not (isinstance(src, types.Array) and src.ndim == 1 and src.layout == "C"
            and isinstance(src.dtype, types.Float)):
        return None
    sig = src.dtype(src, types.intp)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        sptr, vty = _vec_ptr(context, builder, sig.args[0], args[0], args[1])
        v = builder.load(sptr, align=1)
        i32 = ir.IntType(32)
        for width in (4, 2, 1):
            lo = builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(i32, width), list(range(width))))
            hi = builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(i32, width), list(range(width, 2 * width))))
            v = builder.fadd(lo, hi)
        return builder.extract_element(v, ir.Constant(i32, 0))

    return sig, codegen
