"""The grid-flow look-up in C: the same numbers as :meth:`GridFlow.velocity_torch`, several times faster on a CPU.

Why: the look-up is bound by memory latency (the shipped wake's table is 190 MB; every swimmer gathers 4 rows of
it), and in torch it takes about three quarters of the oracle's rollouts in the wake. The torch path gathers, then makes
a dozen passes over ``[N, 16, 3]`` intermediates; this kernel computes each block of 64 swimmers' rows first,
prefetches them, then interpolates from cache in one pass. It performs the torch path's float operations in the
same order (no fused multiply-add: ``-ffp-contract=off``), so the two agree bit for bit; tests/test_flows.py checks
that on periodic and clamped axes, looped and clamped times and both table dtypes.

Used by :class:`~flownav.flows.grid.GridFlow` for float32 positions on the CPU when gcc can build it
(flownav/cbuild.py); otherwise, and on GPUs, the torch path runs, with the same results.
"""

from __future__ import annotations

import ctypes
import warnings
from functools import cache

import torch
from torch import Tensor

from flownav import cbuild

# -ffp-contract=off: the torch path rounds every product and sum, so must this (no fused multiply-add).
FLAGS = (*cbuild.OPTIMISE, "-ffp-contract=off", *cbuild.SHARED)

_BODY = r"""
void grid_velocity_{name}(const {elem}* restrict table, const float* restrict pos, const float* restrict t,
                          float* restrict out, long n, const long* shape, const float* origin, const float* spacing,
                          const int* periodic, const long* strides, float dt, int looped, int threads, long* bad) {{
    long blocks = (n + BLOCK - 1) / BLOCK, nbad = 0;
    #pragma omp parallel for schedule(static) num_threads(threads) if (n > 4096) reduction(+:nbad)
    for (long b = 0; b < blocks; ++b) {{
        long rows[BLOCK][4];
        float w[BLOCK][4];
        int ok[BLOCK];
        long k0 = b * BLOCK, k1 = k0 + BLOCK < n ? k0 + BLOCK : n;
        for (long k = k0; k < k1; ++k) {{  // pass 1: corner rows and weights; prefetch the rows
            long j = k - k0, i[3];
            float f = frame(t[k] / dt, shape[0], looped);
            float f0 = floorf(f);
            f0 = f0 < 0.0f ? 0.0f : f0;
            f0 = f0 > (float)(shape[0] - 1) ? (float)(shape[0] - 1) : f0;
            w[j][0] = f - f0;
            ok[j] = f0 == f0;
            for (int a = 0; a < 3; ++a) {{
                w[j][a + 1] = axis(pos[3 * k + a], origin[a], spacing[a], shape[a + 1], periodic[a], &i[a]);
                ok[j] &= w[j][a + 1] == w[j][a + 1];
            }}
            if (!ok[j]) {{ nbad += 1; continue; }}  // a NaN index: no gather (the torch path raises)
            long row = i[0] * strides[0] + i[1] * strides[1] + i[2] * strides[2] + (long)f0 * strides[3];
            rows[j][0] = row;
            rows[j][1] = row + strides[0];
            rows[j][2] = row + strides[1];
            rows[j][3] = row + strides[0] + strides[1];
            for (int q = 0; q < 4; ++q) {{
                const char* p = (const char*)(table + 12 * rows[j][q]);
                __builtin_prefetch(p);
                __builtin_prefetch(p + 12 * sizeof({elem}) - 1);
            }}
        }}
        for (long k = k0; k < k1; ++k) {{  // pass 2: linear in t, then z, x, y, as the torch path
            long j = k - k0;
            if (!ok[j]) {{ out[3 * k] = out[3 * k + 1] = out[3 * k + 2] = NAN; continue; }}
            float wt = w[j][0], wx = w[j][1], wy = w[j][2], wz = w[j][3], cy[2][3];
            for (int y = 0; y < 2; ++y) {{
                float cx[2][3];
                for (int x = 0; x < 2; ++x) {{
                    const {elem}* r = table + 12 * rows[j][2 * y + x];  // [2 (z), 2 (t), 3]
                    for (int d = 0; d < 3; ++d) {{
                        float z0 = lerp((float)r[d], (float)r[3 + d], wt);
                        float z1 = lerp((float)r[6 + d], (float)r[9 + d], wt);
                        cx[x][d] = lerp(z0, z1, wz);
                    }}
                }}
                for (int d = 0; d < 3; ++d) cy[y][d] = lerp(cx[0][d], cx[1][d], wx);
            }}
            for (int d = 0; d < 3; ++d) out[3 * k + d] = lerp(cy[0][d], cy[1][d], wy);
        }}
    }}
    *bad = nbad;
}}
"""

SOURCE = (
    r"""// flownav.flows.gridkernel: GridFlow's look-up; the float operations of GridFlow.velocity_torch, in its order
#include <math.h>
#define BLOCK 64

static inline float lerp(float a, float b, float w) { return a + w * (b - a); }

static inline float remainder_(float a, float n) {  // torch.remainder for n > 0
    float m = fmodf(a, n);
    return m < 0.0f ? m + n : m;
}

static inline float frame(float f, long T, int looped) {  // GridFlow._frame
    if (looped) return remainder_(f, (float)T);
    f = f < 0.0f ? 0.0f : f;
    return f > (float)(T - 1) ? (float)(T - 1) : f;
}

static inline float axis(float c, float o, float s, long n, int periodic, long* i0) {  // GridFlow._axis
    float g = (c - o) / s, f;
    if (periodic) {
        g = remainder_(g, (float)n);
        f = floorf(g);
        f = f < 0.0f ? 0.0f : f;
        f = f > (float)(n - 1) ? (float)(n - 1) : f;
    } else {
        g = g < 0.0f ? 0.0f : g;
        g = g > (float)(n - 1) ? (float)(n - 1) : g;
        f = floorf(g);
        f = f > (float)(n - 2) ? (float)(n - 2) : f;
    }
    *i0 = f == f ? (long)f : 0;
    return g - f;
}
"""
    + _BODY.format(name="f32", elem="float")
    + _BODY.format(name="f16", elem="_Float16")
)

ELEMENTS = {torch.float32: "f32", torch.float16: "f16"}


@cache
def load() -> ctypes.CDLL | None:
    """The compiled look-up, or None (with one warning) where gcc cannot build it: the torch path then runs."""
    try:
        lib = cbuild.build("flow_kernels", "grid", SOURCE, FLAGS)
    except RuntimeError as e:
        warnings.warn(f"{e}; the grid flows use the torch look-up (the same numbers, slower)", stacklevel=2)
        return None
    p, c_long, c_int = ctypes.c_void_p, ctypes.c_long, ctypes.c_int
    for elem in ELEMENTS.values():  # table, pos, t, out, n, the 5 kernel args, dt, looped, threads, bad
        getattr(lib, f"grid_velocity_{elem}").argtypes = [p, p, p, p, c_long, *[p] * 5, ctypes.c_float, c_int, c_int, p]
    return lib


def usable(table: Tensor, pos: Tensor) -> bool:
    return table.device.type == "cpu" and pos.dtype == torch.float32 and table.dtype in ELEMENTS and load() is not None


def velocity(flow, pos: Tensor, t: Tensor) -> Tensor:
    """``flow.velocity_torch(pos, t)`` for a :class:`GridFlow` ``flow`` (``usable`` for its table and ``pos``)."""
    pos = pos.contiguous()
    t = t.to(pos.dtype).reshape(-1).contiguous()
    if t.shape[0] != pos.shape[0]:  # the kernel reads one time per row
        raise ValueError(f"the grid flow needs one time per position: got {t.shape[0]} for {pos.shape[0]} positions")
    out = torch.empty_like(pos)
    bad = torch.zeros(1, dtype=torch.long)
    args = flow._kernel_args
    getattr(load(), f"grid_velocity_{ELEMENTS[flow._table.dtype]}")(
        flow._table.data_ptr(),
        pos.data_ptr(),
        t.data_ptr(),
        out.data_ptr(),
        pos.shape[0],
        *(a.data_ptr() for a in args),
        flow.dt,
        int(flow.time_mode == "looped"),
        torch.get_num_threads(),
        bad.data_ptr(),
    )
    if int(bad):
        raise ValueError(
            f"the grid flow was asked for its velocity at {int(bad)} non-finite positions or times: "
            "a swimmer's state went non-finite before the look-up"
        )
    return out
