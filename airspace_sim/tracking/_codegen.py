"""Model-specialised IMM step kernels (paper §IV), generated as straight-line numba code.

The generic kernel in :mod:`._kernels` loops over the model sizes with the tracker index
innermost: each of its hundreds of small loops pays a loop set-up, and the sparsity of
``F`` is read from arrays. Here the whole cycle for one tracker is written out as scalar
statements for one model *structure* — the sizes ``M, n, m`` and where ``F_j`` and ``H``
are non-zero; the values stay run-time arguments — and that body sits inside one loop over
the ``W`` trackers of a chunk. LLVM vectorises the loop as a whole (one tracker per SIMD
lane), and the model's zeros cost nothing.

Slots as in :mod:`._kernels`: a chunk without a live lane is skipped, a free lane gets no
measurement (and a finite dummy value) and its state is not written back.

Per chunk: (Z) gather the measurements; (A) mixing, prediction, innovation, ``d²`` and
``det S`` — no calls, vectorised; (L) logarithms, the gate and the mode probabilities —
``log``/``exp`` are libm calls, so this loop runs a tracker at a time; (B) the update,
recomputing ``P Hᵀ`` and ``S⁻¹`` from the stored prediction (the same operations, so the
same bits) rather than storing them, and the combination; then block copies write the
chunk's new state back in place (only the upper triangle of each ``P_j`` is stored; lane
by lane in a chunk with free lanes) and (S) scatters the outputs of the live slots. Every intermediate of a chunk lives in one flat work
array indexed at literal offsets, so LLVM can prove that different rows never overlap
(distinct arrays would each need a run-time alias check, of which it allows only a few).

Every tracker goes through exactly the operations of :func:`._kernels.imm_step_kernel`, in
the same order, without ``fastmath``: the two kernels give the same bits (tested), and a
tracker's result does not depend on its lane, chunk or batch.

Compilation time is what limits this approach (numba's passes are slow on thousands of
statements, and some are quadratic in re-assigned names and in blocks): the generated code
assigns every name once (:class:`_Emitter` versions them), gives each loop its own index
variable and replaces conditional expressions by an LLVM ``select`` (:func:`select`).
The source is written to a file in a cache directory (``$AIRSPACE_SIM_CACHE_DIR``, else
``~/.cache/airspace_sim/kernels``), so that numba's on-disk cache works across processes:
a kernel is compiled once per model structure and chunk width.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
from numba import types
from numba.extending import intrinsic

#: Bump when the generated code changes, so stale cached sources are not reused.
_VERSION = 13

#: Trackers per chunk. The loop body holds a whole tracker, so the chunk only needs to fill
#: the SIMD lanes a few times over; 16 keeps a chunk's work array in the L1 cache.
CHUNK = 16

#: Largest generated kernel "auto" accepts, in multiplications written out. Compilation
#: takes about 5 s + 10 ms per multiplication (2-core Xeon): 3 modes × 5 states with the
#: coordinated-turn sparsity is ~1300 (~20 s), dense 3 × 6 models ~3200 (~36 s).
AUTO_MAX_PRODUCTS = 2000

_KERNELS: dict = {}
_SOURCES: dict = {}


@intrinsic
def select(typingctx, cond, a, b):
    """``a if cond else b`` as one LLVM ``select`` (both operands evaluated): no branch, so
    the loop still vectorises, and no extra blocks in numba's IR, whose SSA pass is
    quadratic in them and would dominate the compilation time."""
    if not isinstance(cond, types.Boolean) or not all(isinstance(t, types.Float) for t in (a, b)):
        return None
    sig = types.float64(cond, a, b)

    def codegen(context, builder, signature, args):
        c, x, y = args  # c is an i1
        x = context.cast(builder, x, signature.args[1], types.float64)
        y = context.cast(builder, y, signature.args[2], types.float64)
        return builder.select(c, x, y)

    return sig, codegen


_ASSIGN = re.compile(r"^(\w+|wk\[[^\]]*\]) = (.*)$")
_NAME = re.compile(r"(?<![.\w])[A-Za-z_]\w*")


class _Emitter:
    """Lines of source. With ``ssa`` set (straight-line code only), a name assigned again
    gets a fresh version: numba's SSA reconstruction is quadratic in re-assigned names
    and would take most of the compilation time."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.level = 0
        self.ssa = False
        self._version: dict = {}
        self._current: dict = {}
        self.lv = None

    def __call__(self, line: str = "") -> None:
        if self.lv:
            line = re.sub(r"\bw\b", self.lv, line)
        if self.ssa and line and not _ASSIGN.match(line):  # a condition: rename uses only
            line = _NAME.sub(lambda mt: self._current.get(mt.group(0), mt.group(0)), line)
        elif self.ssa and line:
            target, expr = _ASSIGN.match(line).groups()
            expr = _NAME.sub(lambda mt: self._current.get(mt.group(0), mt.group(0)), expr)
            if not target.startswith("wk["):
                v = self._version.get(target, -1) + 1
                self._version[target] = v
                self._current[target] = new = f"{target}__{v}" if v else target
                target = new
            line = f"{target} = {expr}"
        self.lines.append("    " * self.level + line if line else "")

    def loop(self, var: str, count) -> None:
        """Open ``for var in range(count):``; inside it, ``w`` in a line stands for ``var``
        (every loop has its own variable: a name bound by several loops is re-assigned)."""
        self.lv = None
        self(f"for {var} in range({count}):")
        self.lv = var
        self.level += 1

    def scope(self, on: bool) -> None:
        """Start (on) or end a straight-line loop body. Versions go on counting across
        loops, so that no name is assigned in two loops either."""
        self.ssa = on
        self._current.clear()

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _sel(c: str, a: str, b: str) -> str:
    """Source of ``a if c else b`` as a branch-free :func:`select`."""
    return f"select({c}, {a}, {b})"


def _sum(terms: list[str]) -> str:
    """``((0.0 + t0) + t1) + …``: the generic kernel's accumulation order, zero start
    included (``0.0 + x`` turns ``-0.0`` into ``+0.0``)."""
    s = "0.0"
    for t in terms:
        s = f"({s} + {t})"
    return s


class _Layout:
    """Row offsets (in units of W) of each quantity in the per-chunk work array."""

    def __init__(self) -> None:
        self.size = 0

    def take(self, k: int) -> int:
        o = self.size
        self.size += k
        return o


def generate(M: int, n: int, m: int, F_pattern, H_pattern, W: int) -> str:
    """Python source of the step kernel ``imm_step`` for one model structure.

    F_pattern: per mode, the (row, col) of the non-zeros of F_j in the order of the
    kernel's ``Fv[j, e]``; H_pattern: the (row, col) of the non-zeros of H in the order of
    ``Hv[e]``. The kernel takes the arguments of :func:`._kernels.imm_step_kernel`'s (one
    signature for both kernels; ``ct`` and ``dt`` are unused: every mode is linear).
    """
    up = [(k, l) for k in range(n) for l in range(k, n)]  # upper triangle, row-major
    lay = _Layout()
    o_z = lay.take(m)
    o_have = lay.take(1)
    o_cbar = lay.take(M)
    o_xp = [lay.take(n) for _ in range(M)]
    o_pp = [lay.take(len(up)) for _ in range(M)]
    o_d2 = lay.take(M)
    o_det = lay.take(M * (1 if m <= 2 else m))
    o_nis = lay.take(1)
    o_ll = lay.take(M)
    o_mu = lay.take(M)
    o_use = lay.take(1)
    o_gated = lay.take(1)
    o_xc = lay.take(n)
    o_xs = lay.take(M * n)  # new state of the chunk, as xs (M, n, W) and Ps (M, T, W)
    o_ps = lay.take(M * len(up))
    o_pc = lay.take(len(up))
    NV = lay.size
    upi = {kl: i for i, kl in enumerate(up)}

    def wk(row: int) -> str:
        return f"wk[{row * W} + w]"

    # the chunk's state, flat: xs (C, M, n, W), Ps (C, M, T, W) with the T = n(n+1)/2
    # entries of each upper triangle (row-major), mus (C, M, W)
    T = len(up)
    SX, SP, SM = M * n * W, M * T * W, M * W

    def xin(i, k):
        return f"xf[cx + {(i * n + k) * W} + w]"

    def pin(i, k, l):
        return f"pf[cp + {(i * T + upi[(k, l)]) * W} + w]"

    def muin(i):
        return f"mf[cm + {i * W} + w]"

    e = _Emitter()
    e("import math")
    e("import numpy as np")
    e("from numba import njit")
    e("from airspace_sim.tracking._codegen import select")
    e()
    e("_LOG_2PI = math.log(2.0 * math.pi)")
    e()
    e()
    e('@njit(cache=True, error_model="numpy")')
    e("def imm_step(Fr, Fc, Fv, Fnnz, Q, U, ct, dt, Hr, Hc, Hv, R, Pi, gate_d2,")
    e("             z, alive, xs, Ps, mus, x_o, P_o, mu_o, nis_o, ll_o, gated_o):")
    e.level += 1
    e(
        f'"""IMM step for M={M}, n={n}, m={m}, W={W} (generated by airspace_sim.tracking._codegen)."""'
    )
    e(f"half_m_log2pi = 0.5 * {m} * _LOG_2PI")
    # model values as scalars, loop invariant
    for j in range(M):
        for q, _ in enumerate(F_pattern[j]):
            e(f"f{j}_{q} = Fv[{j}, {q}]")
        for k, l in up:
            e(f"q{j}_{k}_{l} = Q[{j}, {k}, {l}]")
        for k in range(n):
            e(f"u{j}_{k} = U[{j}, {k}]")
    for q, _ in enumerate(H_pattern):
        e(f"h{q} = Hv[{q}]")
    for a in range(m):
        for a2 in range(a, m):
            e(f"r{a}_{a2} = R[{a}, {a2}]")
    for i in range(M):
        for j in range(M):
            e(f"pi{i}_{j} = Pi[{i}, {j}]")
    e("xf = xs.reshape(xs.size)")
    e("pf = Ps.reshape(Ps.size)")
    e("mf = mus.reshape(mus.size)")
    e(f"wk = np.empty({NV * W})")
    e("for ch in range(xs.shape[0]):")
    e.level += 1
    e(f"b0 = ch * {W}")
    # live lanes of the chunk; a free chunk costs nothing
    e("nl = 0")
    e(f"for wC in range({W}):")
    e("    if alive[b0 + wC]:")
    e("        nl += 1")
    e("if nl == 0:")
    e("    continue")
    e(f"cx = ch * {SX}")
    e(f"cp = ch * {SP}")
    e(f"cm = ch * {SM}")
    # ---- measurements of the chunk
    e.loop("wZ", W)
    e.scope(True)
    e("bZ = b0 + w")
    e("lv = alive[bZ]")
    for a in range(m):  # free lanes: no measurement, and a finite dummy value
        e(f"v{a} = {_sel('lv', f'z[bZ, {a}]', '0.0')}")
        e(f"{wk(o_z + a)} = v{a}")
    ok = " & ".join(["lv"] + [f"math.isfinite(v{a})" for a in range(m)])
    e(f"{wk(o_have)} = {_sel(ok, '1.0', '0.0')}")
    e.scope(False)
    e.level -= 1

    # ------------------------------------------------------------ loop A
    e.loop("wA", W)
    e.scope(True)
    for i in range(M):
        e(f"mu{i} = {muin(i)}")
    for a in range(m):
        e(f"z{a} = {wk(o_z + a)}")
    # step 1: c̄_j and μ_{i|j}
    for j in range(M):
        e(f"cb{j} = {_sum([f'pi{i}_{j} * mu{i}' for i in range(M)])}")
        e(f"{wk(o_cbar + j)} = cb{j}")
        for i in range(M):
            ee = "1.0" if i == j else "0.0"
            e(f"om{i}_{j} = {_sel(f'cb{j} > 0.0', f'(pi{i}_{j} * mu{i}) / cb{j}', ee)}")
    for i in range(M):
        for k in range(n):
            e(f"x{i}_{k} = {xin(i, k)}")
    for j in range(M):
        # step 2: mixed initial conditions
        for k in range(n):
            e(f"a{k} = {_sum([f'x{i}_{k} * om{i}_{j}' for i in range(M)])}")
        for i in range(M):
            for k in range(n):
                e(f"d{i}_{k} = x{i}_{k} - a{k}")
        for k, l in up:
            ts = [f"om{i}_{j} * (d{i}_{k} * d{i}_{l} + {pin(i, k, l)})" for i in range(M)]
            e(f"p{k}_{l} = {_sum(ts)}")

        def P0(k, l):
            return f"p{min(k, l)}_{max(k, l)}"

        # step 3a: prediction over the non-zeros of F_j
        rows: dict = {r: [] for r in range(n)}
        for q, (r, c) in enumerate(F_pattern[j]):
            rows[r].append((q, c))
        for r in range(n):
            s = f"u{j}_{r}"
            for q, c in rows[r]:
                s = f"({s} + f{j}_{q} * a{c})"
            e(f"xp{r} = {s}")
            e(f"{wk(o_xp[j] + r)} = xp{r}")
        for r in range(n):
            for l in range(n):
                e(f"fp{r}_{l} = {_sum([f'f{j}_{q} * {P0(c, l)}' for q, c in rows[r]])}")
        for k, r in up:
            s = _sum([f"fp{k}_{c} * f{j}_{q}" for q, c in rows[r]])
            e(f"pp{k}_{r} = ({s} + q{j}_{k}_{r})")
            e(f"{wk(o_pp[j] + upi[(k, r)])} = pp{k}_{r}")
        _emit_innovation(e, j, n, m, H_pattern, lambda k, l: f"pp{min(k, l)}_{max(k, l)}", "xp")
        # d², det
        e(f"{wk(o_d2 + j)} = d2")
        if m <= 2:
            e(f"{wk(o_det + j)} = dt")
        else:
            for a in range(m):
                e(f"{wk(o_det + j * m + a)} = L{a}_{a}")
        for a in range(m):
            e(f"zh{j}_{a} = zh{a}")
            for a2 in range(a, m):
                e(f"S{j}_{a}_{a2} = s{a}_{a2}")
    # mixture innovation NIS with c̄
    for a in range(m):
        e(f"zb{a} = {_sum([f'cb{j} * zh{j}_{a}' for j in range(M)])}")
    for a in range(m):
        for a2 in range(a, m):
            ts = [f"cb{j} * (S{j}_{a}_{a2} + (zh{j}_{a} - zb{a}) * (zh{j}_{a2} - zb{a2}))"
                  for j in range(M)]  # fmt: skip
            e(f"s{a}_{a2} = {_sum(ts)}")
    for a in range(m):
        e(f"dz{a} = z{a} - zb{a}")
    _emit_inverse(e, m, want_det=False)
    nis_terms = [
        f"dz{a} * si{min(a, a2)}_{max(a, a2)} * dz{a2}" for a in range(m) for a2 in range(m)
    ]
    e(f"{wk(o_nis)} = {_sum(nis_terms)}")
    e.level -= 1
    e.scope(False)

    # ------------------------------------------------------------ loop L (libm calls)
    e.loop("wL", W)
    e.scope(True)
    for j in range(M):
        e(f"d2r{j} = {wk(o_d2 + j)}")
        if m == 1:
            e(f"sd{j} = {wk(o_det + j)}")
            e(f"ld{j} = {_sel(f'sd{j} > 0.0', f'math.log(sd{j})', 'np.nan')}")
        elif m == 2:
            e(f"ld{j} = math.log({wk(o_det + j)})")  # NaN where S_j is not positive definite
        else:
            ts = []
            for a in range(m):
                e(f"la{j}_{a} = {wk(o_det + j * m + a)}")
                ts.append(_sel(f"la{j}_{a} > 0.0", f"2.0 * math.log(la{j}_{a})", "np.nan"))
            e(f"ld{j} = {_sum(ts)}")
        e(f"ok{j} = (ld{j} == ld{j}) & (d2r{j} < np.inf)")
        e(f"d2{j} = {_sel(f'ok{j}', f'd2r{j}', 'np.nan')}")
        e(f"ll{j} = -0.5 * (d2{j} + ld{j}) - half_m_log2pi")
        e(f"{wk(o_ll + j)} = ll{j}")
        e(f"cb{j} = {wk(o_cbar + j)}")
        # inside the gate of a reachable mode (a NaN d² is inside none)
        e(f"in{j} = (d2{j} <= gate_d2) & (cb{j} > 0.0)")
    e(f"inside = {' | '.join(f'in{j}' for j in range(M))}")
    e(f"have = {wk(o_have)} != 0.0")
    e("use = have & inside")
    e(f"{wk(o_use)} = {_sel('use', '1.0', '0.0')}")
    e(f"{wk(o_gated)} = {_sel('have & (inside == False)', '1.0', '0.0')}")
    # (a branch: the exponentials are only worth computing where the measurement is used)
    e("if use:")
    e.level += 1
    e("mx = -np.inf")
    for j in range(M):
        e(f"mx = {_sel(f'(cb{j} > 0.0) & (ll{j} > mx)', f'll{j}', 'mx')}")
    for j in range(M):
        e(
            f"ee{j} = {_sel(f'(cb{j} > 0.0) & (ll{j} > -np.inf)', f'cb{j} * math.exp(ll{j} - mx)', '0.0')}"
        )
    e(f"s = {_sum([f'ee{j}' for j in range(M)])}")
    for j in range(M):
        e(f"{wk(o_mu + j)} = ee{j} / s")
    e.level -= 1
    e("else:")
    e.level += 1
    for j in range(M):
        e(f"{wk(o_mu + j)} = cb{j}")
    e.level -= 1
    e.scope(False)
    e.level -= 1

    # ------------------------------------------------------------ loop B
    e.loop("wB", W)
    e.scope(True)
    e(f"use = {wk(o_use)} != 0.0")
    for a in range(m):
        e(f"z{a} = {wk(o_z + a)}")
    for j in range(M):
        for k in range(n):
            e(f"xp{k} = {wk(o_xp[j] + k)}")
        for k, l in up:
            e(f"pp{k}_{l} = {wk(o_pp[j] + upi[(k, l)])}")
        _emit_innovation(e, j, n, m, H_pattern, lambda k, l: f"pp{min(k, l)}_{max(k, l)}", "xp")
        # K = P Hᵀ S⁻¹
        for k in range(n):
            for a in range(m):
                ks = _sum([f"ph{k}_{a2} * si{min(a2, a)}_{max(a2, a)}" for a2 in range(m)])
                e(f"K{k}_{a} = {ks}")
        for a in range(m):
            e(f"nu{a} = z{a} - zh{a}")
        for k in range(n):
            e(f"t = {_sum([f'K{k}_{a} * nu{a}' for a in range(m)])}")
            e(f"xu{k} = {_sel('use', f'xp{k} + t', f'xp{k}')}")
            e(f"{wk(o_xs + j * n + k)} = xu{k}")
        # AP = P − K (P Hᵀ)ᵀ
        for k in range(n):
            for l in range(n):
                s = f"pp{min(k, l)}_{max(k, l)}"
                for a in range(m):
                    s = f"({s} - K{k}_{a} * ph{l}_{a})"
                e(f"ap{k}_{l} = {s}")
        # G = K R − AP Hᵀ
        hrows: dict = {a: [] for a in range(m)}
        for q, (a, c) in enumerate(H_pattern):
            hrows[a].append((q, c))
        for k in range(n):
            for a in range(m):
                s = "0.0"
                for q, c in hrows[a]:
                    s = f"({s} - ap{k}_{c} * h{q})"
                for a2 in range(m):
                    s = f"({s} + K{k}_{a2} * r{min(a2, a)}_{max(a2, a)})"
                e(f"G{k}_{a} = {s}")
        for k, l in up:
            s = f"ap{k}_{l}"
            for a in range(m):
                s = f"({s} + G{k}_{a} * K{l}_{a})"
            e(f"t = {s}")
            e(f"pu{j}_{k}_{l} = {_sel('use', 't', f'pp{k}_{l}')}")
            e(f"{wk(o_ps + j * T + upi[(k, l)])} = pu{j}_{k}_{l}")
        for k in range(n):
            e(f"xu{j}_{k} = xu{k}")
    # step 5: combination
    for j in range(M):
        e(f"mn{j} = {wk(o_mu + j)}")
    for k in range(n):
        e(f"xc{k} = {_sum([f'xu{j}_{k} * mn{j}' for j in range(M)])}")
        e(f"{wk(o_xc + k)} = xc{k}")
    for j in range(M):
        for k in range(n):
            e(f"D{j}_{k} = xu{j}_{k} - xc{k}")
    for k, l in up:
        ts = [f"mn{j} * (D{j}_{k} * D{j}_{l} + pu{j}_{k}_{l})" for j in range(M)]
        e(f"{wk(o_pc + upi[(k, l)])} = {_sum(ts)}")
    e.level -= 1
    e.scope(False)
    # the chunk's new state: rows of wk laid out as the state arrays, so that these are
    # block copies (writing the state arrays from loop B would defeat its vectorisation:
    # too many run-time alias checks); lane by lane where some lanes are free (they keep
    # their state)
    e(f"if nl == {W}:")
    e(f"    xf[cx : cx + {SX}] = wk[{o_xs * W} : {(o_xs + M * n) * W}]")
    e(f"    pf[cp : cp + {SP}] = wk[{o_ps * W} : {(o_ps + M * T) * W}]")
    e(f"    mf[cm : cm + {SM}] = wk[{o_mu * W} : {(o_mu + M) * W}]")
    e("else:")
    e(f"    for wW in range({W}):")
    e("        if alive[b0 + wW]:")
    for name, base, off, rows in (("xf", "cx", o_xs, M * n), ("pf", "cp", o_ps, M * T),
                                  ("mf", "cm", o_mu, M)):  # fmt: skip
        e(f"            for rW in range({rows}):")
        e(f"                {name}[{base} + rW * {W} + wW] = wk[({off} + rW) * {W} + wW]")
    # ---- scatter to the (capacity, ...) outputs, live slots only
    e.loop("wS", W)
    e("bS = b0 + w")
    e("if not alive[bS]:")
    e("    continue")
    e(f"haveS = {wk(o_have)} != 0.0")
    e(f"gated_o[bS] = {wk(o_gated)} != 0.0")
    e(f"nis_o[bS] = {_sel('haveS', wk(o_nis), 'np.nan')}")
    for j in range(M):
        e(f"mu_o[bS, {j}] = {wk(o_mu + j)}")
        e(f"ll_o[bS, {j}] = {_sel('haveS', wk(o_ll + j), 'np.nan')}")
    for k in range(n):
        e(f"x_o[bS, {k}] = {wk(o_xc + k)}")
    for k, l in up:
        v = wk(o_pc + upi[(k, l)])
        e(f"P_o[bS, {k}, {l}] = {v}")
        if k != l:
            e(f"P_o[bS, {l}, {k}] = {v}")
    e.level -= 2
    return e.text()


def _emit_innovation(e: _Emitter, j, n, m, H_pattern, P, xname) -> None:
    """ẑ = H x, P Hᵀ, S = H P Hᵀ + R, S⁻¹ (si), det S (dt) or Cholesky diagonal (L),
    and for loop A the innovation's d² — over the non-zeros of H."""
    hrows: dict = {a: [] for a in range(m)}
    for q, (a, c) in enumerate(H_pattern):
        hrows[a].append((q, c))
    for a in range(m):
        e(f"zh{a} = {_sum([f'h{q} * {xname}{c}' for q, c in hrows[a]])}")
        for k in range(n):
            e(f"ph{k}_{a} = {_sum([f'{P(k, c)} * h{q}' for q, c in hrows[a]])}")
    for a in range(m):
        for a2 in range(a, m):
            s = f"r{a}_{a2}"
            for q, c in hrows[a]:
                s = f"({s} + h{q} * ph{c}_{a2})"
            e(f"s{a}_{a2} = {s}")
    _emit_inverse(e, m, want_det=True)
    for a in range(m):
        e(f"nu{a} = z{a} - zh{a}")
    ts = [f"nu{a} * si{min(a, a2)}_{max(a, a2)} * nu{a2}" for a in range(m) for a2 in range(m)]
    e(f"d2 = {_sum(ts)}")


def _emit_inverse(e: _Emitter, m: int, want_det: bool) -> None:
    """si{a}_{a2} (upper) = s⁻¹ of the symmetric s{a}_{a2}, as ``_kernels._inv_logdet``;
    with want_det, ``dt`` (m ≤ 2: det S, NaN unless positive definite) or the Cholesky
    diagonal ``L{a}_{a}`` (m > 2) for the log-determinant."""
    if m == 1:
        e("si0_0 = 1.0 / s0_0")
        if want_det:
            e("dt = s0_0")
    elif m == 2:
        e("dt = s0_0 * s1_1 - s0_1 * s0_1")
        e("si0_0 = s1_1 / dt")
        e("si0_1 = -s0_1 / dt")
        e("si1_1 = s0_0 / dt")
        if want_det:
            e(f"dt = {_sel('(dt > 0.0) & (s0_0 > 0.0)', 'dt', 'np.nan')}")
    else:
        for i in range(m):
            for j in range(i + 1):
                s = f"s{j}_{i}"
                for k in range(j):
                    s = f"({s} - L{i}_{k} * L{j}_{k})"
                if i == j:
                    e(f"t = {s}")
                    e(f"L{i}_{i} = {_sel('t > 0.0', 'math.sqrt(t)', 'np.nan')}")
                else:
                    e(f"L{i}_{j} = {s} / L{j}_{j}")
        for i in range(m):
            e(f"Li{i}_{i} = 1.0 / L{i}_{i}")
            for j in range(i):
                s = "0.0"
                for k in range(j, i):
                    s = f"({s} - L{i}_{k} * Li{k}_{j})"
                e(f"Li{i}_{j} = {s} / L{i}_{i}")
        for i in range(m):
            for j in range(i, m):
                e(f"si{i}_{j} = {_sum([f'Li{k}_{i} * Li{k}_{j}' for k in range(j, m)])}")


def _cache_dir() -> Path:
    base = os.environ.get("AIRSPACE_SIM_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(xdg) / "airspace_sim" / "kernels"


def _load(source: str, name: str):
    """Import ``source`` as module ``name`` from a file (numba caches per file)."""
    for d in (_cache_dir(), Path(tempfile.gettempdir()) / f"airspace_sim-kernels-{os.getuid()}"):
        try:
            d.mkdir(parents=True, exist_ok=True)
            path = d / f"{name}.py"
            if not path.exists() or path.read_text() != source:
                tmp = d / f".{name}.{os.getpid()}.tmp"
                tmp.write_text(source)
                os.replace(tmp, path)  # atomic: parallel workers never see half a file
            break
        except OSError:
            continue
    else:  # no writable directory: compile in memory, without the on-disk cache
        namespace: dict = {}
        code = compile(source.replace("cache=True", "cache=False"), name, "exec")
        exec(code, namespace)  # noqa: S102 - our own generated source
        return namespace["imm_step"]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module.imm_step


def _structure(F: np.ndarray, H: np.ndarray):
    F_pattern = tuple(tuple(zip(*(a.tolist() for a in np.nonzero(f)))) for f in F)
    H_pattern = tuple(zip(*(a.tolist() for a in np.nonzero(H))))
    return F.shape[0], F.shape[1], H.shape[0], F_pattern, H_pattern


def step_kernel(F: np.ndarray, H: np.ndarray, W: int = CHUNK, max_products: int | None = None):
    """The generated IMM step kernel for the structure (sizes and non-zeros) of F (M, n, n)
    and H (m, n), chunk width W; compiled once per structure (then loaded from the disk
    cache). None if its code has more than ``max_products`` multiplications."""
    M, n, m, F_pattern, H_pattern = _structure(F, H)
    key = (M, n, m, F_pattern, H_pattern, W, _VERSION)
    if key not in _SOURCES:
        _SOURCES[key] = generate(M, n, m, F_pattern, H_pattern, W)
    source = _SOURCES[key]
    if max_products is not None and source.count(" * ") > max_products:
        return None
    if key not in _KERNELS:
        digest = hashlib.sha1(repr(key).encode()).hexdigest()[:16]
        _KERNELS[key] = _load(source, f"_airspace_sim_imm_{M}_{n}_{m}_{digest}")
    return _KERNELS[key]
