"""Numba kernels of the batched IMM (paper §IV). Internal: use :class:`airspace_sim.tracking.IMM`.

:func:`imm_step_kernel` returns the step kernel (``M`` modes, ``n`` states, ``m``
measurement components). The mode-conditioned state lives in *slots* of a chunked
structure-of-arrays layout, ``(C, ..., W)``: ``C`` chunks of ``W`` lanes, slot ``s`` in
chunk ``s // W``, lane ``s % W`` (:class:`airspace_sim.tracking.slot_imm.SlotIMM` owns it).
Each step of the IMM cycle is a set of loops whose innermost loop runs over the ``W``
lanes of a chunk — LLVM turns it into SIMD code, one tracker per lane — with the model
sizes as (run-time) outer loop bounds and ``W`` a compile-time constant. Work buffers are
allocated once per call; the combined estimate and the per-tracker diagnostics are
written out by slot, in the usual (capacity, ...) layout.

Free slots: an ``alive`` mask (capacity,) marks the live lanes. A chunk without a live
lane is skipped. A free lane inside a live chunk is computed with the others (the SIMD
lanes are there anyway) as a prediction without measurement from its own stored state, but
nothing of it is written back: its state stays what it was when it was freed (benign
values, set by the owner), so however many steps pass it can neither grow nor become NaN,
and its outputs are left as they are.

Determinism: no ``fastmath`` (so no reassociation and no FMA contraction) and no parallel
reduction. Every lane does the same sequence of IEEE operations on its own tracker's data
(``exp``/``log`` are scalar libm calls per tracker), so a tracker's result is the same bits
whichever slot it lands in, whatever the other slots hold, run after run.

Transition matrices are also passed as the list of their non-zero entries: the
coordinated-turn matrices are mostly zeros, and ``F P Fᵀ`` over the non-zeros only is 2–3×
cheaper. The measurement matrix is handled the same way.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.tracking.coordinated_turn import ct_terms

_LOG_2PI = math.log(2.0 * math.pi)

#: Trackers per chunk (SIMD lanes × unroll), a multiple of 8. Larger amortises each small
#: loop's set-up better (64 is ~1.5× faster than 32 at B = 10⁴); a batch smaller than one
#: chunk still costs a whole chunk.
CHUNK = 64


@njit(cache=True, error_model="numpy")
def _inv_logdet(S, Si, logdet, L, Li, want_log):
    """For each lane w of S (m, m, W), symmetric positive definite, its inverse Si (m, m, W)
    and (if ``want_log``) log-determinant logdet (W,); NaN in ``logdet`` where S is not
    positive definite. Closed form for m ≤ 2, Cholesky otherwise (L, Li: (m, m, W) work
    arrays)."""
    m = S.shape[0]
    W = S.shape[2]
    if m == 1:
        for w in range(W):
            s = S[0, 0, w]
            Si[0, 0, w] = 1.0 / s
            if want_log:
                logdet[w] = math.log(s) if s > 0.0 else np.nan
    elif m == 2:
        for w in range(W):
            a = S[0, 0, w]
            b = S[0, 1, w]
            d = S[1, 1, w]
            det = a * d - b * b
            Si[0, 0, w] = d / det
            Si[0, 1, w] = -b / det
            Si[1, 0, w] = -b / det
            Si[1, 1, w] = a / det
            if want_log:
                logdet[w] = math.log(det) if (det > 0.0 and a > 0.0) else np.nan
    else:
        for w in range(W):
            logdet[w] = 0.0
        for i in range(m):
            for j in range(i + 1):
                for w in range(W):
                    s = S[i, j, w]
                    for k in range(j):
                        s -= L[i, k, w] * L[j, k, w]
                    if i == j:
                        if s > 0.0:
                            L[i, i, w] = math.sqrt(s)
                        else:
                            L[i, i, w] = np.nan
                    else:
                        L[i, j, w] = s / L[j, j, w]
            if want_log:
                for w in range(W):
                    logdet[w] += 2.0 * math.log(L[i, i, w]) if L[i, i, w] > 0.0 else np.nan
        # Li = L⁻¹ (lower triangular), Si = Liᵀ Li
        for i in range(m):
            for w in range(W):
                Li[i, i, w] = 1.0 / L[i, i, w]
            for j in range(i):
                for w in range(W):
                    s = 0.0
                    for k in range(j, i):
                        s -= L[i, k, w] * Li[k, j, w]
                    Li[i, j, w] = s / L[i, i, w]
        for i in range(m):
            for j in range(i, m):
                for w in range(W):
                    s = 0.0
                    for k in range(j, m):
                        s += Li[k, i, w] * Li[k, j, w]
                    Si[i, j, w] = s
                    Si[j, i, w] = s


@njit(cache=True, error_model="numpy")
def _ct_predict(x0, P0, dt, u, Q, XP, PP, J, FP):
    """EKF prediction of the estimated-rate coordinated-turn mode (:mod:`.coordinated_turn`)
    for every lane: x0 (5, W), P0 (5, 5, W) (full) in; XP (5, W) = f(x0) + u,
    PP (5, 5, W) = J P0 Jᵀ + Q out; J, FP (5, 5, W) work arrays. u (5,), Q (5, 5)."""
    n = x0.shape[0]
    W = x0.shape[1]
    for k in range(n):
        for l in range(n):
            for w in range(W):
                J[k, l, w] = 0.0
    for w in range(W):
        vx = x0[1, w]
        vy = x0[3, w]
        s, c, ds, dc, co, si = ct_terms(x0[4, w], dt)
        XP[0, w] = x0[0, w] + s * vx - c * vy + u[0]
        XP[1, w] = co * vx - si * vy + u[1]
        XP[2, w] = x0[2, w] + c * vx + s * vy + u[2]
        XP[3, w] = si * vx + co * vy + u[3]
        XP[4, w] = x0[4, w] + u[4]
        for k in range(5, n):
            # a 6-state model's along-track acceleration: not this mode's, pinned to u (J row 0)
            XP[k, w] = u[k]
        J[0, 0, w] = 1.0
        J[0, 1, w] = s
        J[0, 3, w] = -c
        J[0, 4, w] = ds * vx - dc * vy
        J[1, 1, w] = co
        J[1, 3, w] = -si
        J[1, 4, w] = -dt * (si * vx + co * vy)
        J[2, 1, w] = c
        J[2, 2, w] = 1.0
        J[2, 3, w] = s
        J[2, 4, w] = dc * vx + ds * vy
        J[3, 1, w] = si
        J[3, 3, w] = co
        J[3, 4, w] = dt * (co * vx - si * vy)
        J[4, 4, w] = 1.0
    for k in range(n):
        for l in range(n):
            for w in range(W):
                FP[k, l, w] = 0.0
            for i in range(n):
                for w in range(W):
                    FP[k, l, w] += J[k, i, w] * P0[i, l, w]
    for k in range(n):
        for l in range(k, n):
            for w in range(W):
                PP[k, l, w] = Q[k, l]
            for i in range(n):
                for w in range(W):
                    PP[k, l, w] += FP[k, i, w] * J[l, i, w]
        for l in range(k):
            for w in range(W):
                PP[k, l, w] = PP[l, k, w]


#: Below this |ΩT| (rad) the along-track terms b_s, b_c use their series (error ~|ΩT|⁶
#: relative; the closed forms lose ~ε/|ΩT|³ to cancellation above it).
_CTA_SMALL = 1e-2
#: The along-track direction is v / max(|v|, this) (m/s): finite for a track at rest.
CTA_MIN_SPEED = 1.0


@njit(cache=True, error_model="numpy")
def _cta_terms(omega, T):
    """``s, c, ∂s/∂Ω, ∂c/∂Ω, cos ΩT, sin ΩT, b_s, b_c, ∂b_s/∂Ω, ∂b_c/∂Ω`` of the
    coordinated turn with along-track acceleration (:mod:`.along_track`) at turn rate
    ``omega`` (rad/s) over ``T`` s: ``s, c`` as :func:`.coordinated_turn.ct_terms` (the
    same formulas, here so that this module's cached kernels call only its own helpers)
    and ``b_s = ∫₀ᵀ t cos Ωt dt``, ``b_c = ∫₀ᵀ t sin Ωt dt``; exact through Ω = 0 by
    series."""
    u = omega * T
    co = math.cos(u)
    si = math.sin(u)
    u2 = u * u
    if abs(u) < 1e-3:  # coordinated_turn._SMALL
        s = T * (1.0 - u2 / 6.0)
        c = T * u * (0.5 - u2 / 24.0)
        ds = T * T * u * (-1.0 / 3.0 + u2 / 30.0)
        dc = T * T * (0.5 - u2 / 8.0)
    else:
        s = si / omega
        c = (1.0 - co) / omega
        ds = (u * co - si) / (omega * omega)
        dc = (u * si - (1.0 - co)) / (omega * omega)
    T2 = T * T
    if abs(u) < _CTA_SMALL:
        bs = T2 * (0.5 - u2 / 8.0 + u2 * u2 / 144.0)
        bc = T2 * u * (1.0 / 3.0 - u2 / 30.0 + u2 * u2 / 840.0)
        dbs = T2 * T * u * (-0.25 + u2 / 36.0 - u2 * u2 / 960.0)
        dbc = T2 * T * (1.0 / 3.0 - u2 / 10.0 + u2 * u2 / 168.0)
    else:
        w2 = omega * omega
        bs = T * si / omega - (1.0 - co) / w2
        bc = si / w2 - T * co / omega
        dbs = T2 * co / omega - 2.0 * T * si / w2 + 2.0 * (1.0 - co) / (w2 * omega)
        dbc = T2 * si / omega + 2.0 * T * co / w2 - 2.0 * si / (w2 * omega)
    return s, c, ds, dc, co, si, bs, bc, dbs, dbc


@njit(cache=True, error_model="numpy")
def _cta_predict(x0, P0, dt, u, Q, XP, PP, J, FP):
    """EKF prediction of the coordinated turn with along-track acceleration
    (:mod:`.along_track`, state ``[x, vx, y, vy, Ω, a]``) for every lane: x0 (6, W),
    P0 (6, 6, W) (full) in; XP (6, W) = f(x0) + u, PP (6, 6, W) = J P0 Jᵀ + Q out;
    J, FP (6, 6, W) work arrays. u (6,), Q (6, 6)."""
    n = x0.shape[0]
    W = x0.shape[1]
    for k in range(n):
        for l in range(n):
            for w in range(W):
                J[k, l, w] = 0.0
    for w in range(W):
        vx = x0[1, w]
        vy = x0[3, w]
        a = x0[5, w]
        s, c, ds, dc, co, si, bs, bc, dbs, dbc = _cta_terms(x0[4, w], dt)
        sp = math.sqrt(vx * vx + vy * vy)
        # e = v / |v| (the along-track direction) and its Jacobian D = (I − e eᵀ) / |v|
        if sp > CTA_MIN_SPEED:
            ex = vx / sp
            ey = vy / sp
            d11 = (1.0 - ex * ex) / sp
            d12 = -ex * ey / sp
            d22 = (1.0 - ey * ey) / sp
        else:
            ex = vx / CTA_MIN_SPEED
            ey = vy / CTA_MIN_SPEED
            d11 = 1.0 / CTA_MIN_SPEED
            d12 = 0.0
            d22 = 1.0 / CTA_MIN_SPEED
        # B e and T R e: how far the acceleration a moves the position and the velocity
        bex = bs * ex - bc * ey
        bey = bc * ex + bs * ey
        rex = dt * (co * ex - si * ey)
        rey = dt * (si * ex + co * ey)
        XP[0, w] = x0[0, w] + s * vx - c * vy + a * bex + u[0]
        XP[1, w] = co * vx - si * vy + a * rex + u[1]
        XP[2, w] = x0[2, w] + c * vx + s * vy + a * bey + u[2]
        XP[3, w] = si * vx + co * vy + a * rey + u[3]
        XP[4, w] = x0[4, w] + u[4]
        XP[5, w] = a + u[5]
        J[0, 0, w] = 1.0
        J[0, 1, w] = s + a * (bs * d11 - bc * d12)
        J[0, 3, w] = -c + a * (bs * d12 - bc * d22)
        J[0, 4, w] = ds * vx - dc * vy + a * (dbs * ex - dbc * ey)
        J[0, 5, w] = bex
        J[1, 1, w] = co + a * dt * (co * d11 - si * d12)
        J[1, 3, w] = -si + a * dt * (co * d12 - si * d22)
        J[1, 4, w] = -dt * (si * vx + co * vy) - a * dt * rey
        J[1, 5, w] = rex
        J[2, 1, w] = c + a * (bc * d11 + bs * d12)
        J[2, 2, w] = 1.0
        J[2, 3, w] = s + a * (bc * d12 + bs * d22)
        J[2, 4, w] = dc * vx + ds * vy + a * (dbc * ex + dbs * ey)
        J[2, 5, w] = bey
        J[3, 1, w] = si + a * dt * (si * d11 + co * d12)
        J[3, 3, w] = co + a * dt * (si * d12 + co * d22)
        J[3, 4, w] = dt * (co * vx - si * vy) + a * dt * rex
        J[3, 5, w] = rey
        J[4, 4, w] = 1.0
        J[5, 5, w] = 1.0
    for k in range(n):
        for l in range(n):
            for w in range(W):
                FP[k, l, w] = 0.0
            for i in range(n):
                for w in range(W):
                    FP[k, l, w] += J[k, i, w] * P0[i, l, w]
    for k in range(n):
        for l in range(k, n):
            for w in range(W):
                PP[k, l, w] = Q[k, l]
            for i in range(n):
                for w in range(W):
                    PP[k, l, w] += FP[k, i, w] * J[l, i, w]
        for l in range(k):
            for w in range(W):
                PP[k, l, w] = PP[l, k, w]


def _make_imm_step(W):
    """The IMM step for chunk width W.

    W is a closure variable, so a compile-time constant for numba: the innermost loops
    (over the W lanes of a chunk) have a constant trip count and vectorise without
    remainder loops."""

    @njit(cache=True, error_model="numpy")
    def imm_step(
        Fr, Fc, Fv, Fnnz, Q, U, ct, dt, Hr, Hc, Hv, R, Pi, gate_d2,
        z, alive, xs, Ps, mus,
        x_o, P_o, mu_o, nis_o, ll_o, gated_o,
    ):  # fmt: skip
        """One IMM cycle (paper §IV, steps 1–5) for every live slot.

        Model: Fr, Fc, Fv (M, K) row, column and value of the non-zeros of each F_j (the
        first Fnnz[j] of them); Q (M, n, n) symmetric; U (M, n) offsets; ct (M,) int:
        the EKF modes, whose F is not read: 1 the estimated-rate coordinated turn
        (n = 5 or 6, :mod:`.coordinated_turn`), 2 the coordinated turn with along-track
        acceleration (n = 6, :mod:`.along_track`); 0 linear; dt their step in seconds; Hr, Hc, Hv (KH,)
        the non-zeros of H (m, n); R (m, m) symmetric positive definite; Pi (M, M)
        row-stochastic; gate_d2 the chi-square gate on d² (``inf``: no gate).

        State, chunked structure-of-arrays of C chunks (capacity B = C·W slots), updated in
        place in the live lanes: xs (C, M, n, W) mode-conditioned states, Ps (C, M, n, n, W)
        their covariances (upper triangle read), mus (C, M, W) mode probabilities.
        alive (B,) bool: live slots. Measurements z (B, m) by slot (free slots' rows are
        not read). Out, written in the live slots only: x_o (B, n), P_o (B, n, n),
        mu_o (B, M), nis_o (B,), ll_o (B, M), gated_o (B,) bool.
        """
        M = xs.shape[1]
        n = xs.shape[2]
        m = z.shape[1]
        nH = Hr.shape[0]
        half_m_log2pi = 0.5 * m * _LOG_2PI

        cbar = np.empty((M, W))
        om = np.empty((M, M, W))
        x0 = np.empty((n, W))
        P0 = np.empty((n, n, W))
        FP = np.empty((n, n, W))
        J = np.empty((n, n, W))
        zc = np.empty((m, W))
        have = np.empty(W, dtype=np.bool_)
        use = np.empty(W, dtype=np.bool_)
        zh = np.empty((M, m, W))
        nu = np.empty((M, m, W))
        PHt = np.empty((M, n, m, W))
        S = np.empty((M, m, m, W))
        Si = np.empty((M, m, m, W))
        logdet = np.empty((M, W))
        d2 = np.empty((M, W))
        ll = np.empty((M, W))
        K = np.empty((n, m, W))
        AP = np.empty((n, n, W))
        G = np.empty((n, m, W))
        L = np.empty((m, m, W))
        Li = np.empty((m, m, W))
        zbar = np.empty((m, W))
        dz = np.empty((m, W))
        Sbar = np.empty((m, m, W))
        Sbi = np.empty((m, m, W))
        ldb = np.empty(W)
        nis = np.empty(W)
        tmp = np.empty(W)
        D = np.empty((n, W))
        xc = np.empty((n, W))
        Pc = np.empty((n, n, W))
        # the chunk's new state, copied into the state arrays (live lanes) at the end
        XP = np.empty((M, n, W))
        PP = np.empty((M, n, n, W))
        mun = np.empty((M, W))
        live = np.empty(W, dtype=np.bool_)

        for ch in range(xs.shape[0]):
            b0 = ch * W
            nl = 0
            for w in range(W):
                live[w] = alive[b0 + w]
                if live[w]:
                    nl += 1
            if nl == 0:
                continue  # a free chunk costs nothing
            X = xs[ch]
            Pin = Ps[ch]
            mu_c = mus[ch]
            # ---- measurements of the chunk (free lanes: none, and a finite dummy value)
            for w in range(W):
                ok = live[w]
                for a in range(m):
                    zc[a, w] = z[b0 + w, a] if live[w] else 0.0
                    if not math.isfinite(zc[a, w]):
                        ok = False
                have[w] = ok

            # ---- Step 1: mixing probabilities μ_{i|j} = π_ij μ_i / c̄_j, c̄_j = Σ_i π_ij μ_i
            for j in range(M):
                for w in range(W):
                    cbar[j, w] = 0.0
                for i in range(M):
                    p = Pi[i, j]
                    for w in range(W):
                        cbar[j, w] += p * mu_c[i, w]
                for i in range(M):
                    p = Pi[i, j]
                    e = 1.0 if i == j else 0.0
                    for w in range(W):
                        c = cbar[j, w]
                        # an unreachable mode (c̄_j = 0) keeps its own estimate; its μ stays 0
                        om[i, j, w] = (p * mu_c[i, w]) / c if c > 0.0 else e

            for j in range(M):
                # ---- Step 2: mixed initial conditions x0j = Σ_i μ_{i|j} x_i,
                #      P0j = Σ_i μ_{i|j} [P_i + (x_i − x0j)(x_i − x0j)ᵀ]   (upper triangle)
                for k in range(n):
                    for w in range(W):
                        x0[k, w] = 0.0
                    for i in range(M):
                        for w in range(W):
                            x0[k, w] += X[i, k, w] * om[i, j, w]
                for k in range(n):
                    for l in range(k, n):
                        for w in range(W):
                            P0[k, l, w] = 0.0
                for i in range(M):
                    for k in range(n):
                        for w in range(W):
                            D[k, w] = X[i, k, w] - x0[k, w]
                    for k in range(n):
                        for l in range(k, n):
                            for w in range(W):
                                P0[k, l, w] += om[i, j, w] * (D[k, w] * D[l, w] + Pin[i, k, l, w])
                for k in range(n):
                    for l in range(k):
                        for w in range(W):
                            P0[k, l, w] = P0[l, k, w]

                # ---- Step 3a: mode-matched prediction x_j = F_j x0j + u_j,
                #      P_j = F_j P0j F_jᵀ + Q_j, over the non-zeros of F_j; an
                #      estimated-rate mode: x_j = f(x0j) + u_j, P_j = J P0j Jᵀ + Q_j (EKF)
                if ct[j] == 2:
                    _cta_predict(x0, P0, dt, U[j], Q[j], XP[j], PP[j], J, FP)
                elif ct[j]:
                    _ct_predict(x0, P0, dt, U[j], Q[j], XP[j], PP[j], J, FP)
                lin = not ct[j]
                for k in range(n if lin else 0):
                    u = U[j, k]
                    for w in range(W):
                        XP[j, k, w] = u
                    for l in range(n):
                        for w in range(W):
                            FP[k, l, w] = 0.0
                for e in range(Fnnz[j] if lin else 0):
                    r = Fr[j, e]
                    c = Fc[j, e]
                    v = Fv[j, e]
                    for w in range(W):
                        XP[j, r, w] += v * x0[c, w]
                    for l in range(n):
                        for w in range(W):
                            FP[r, l, w] += v * P0[c, l, w]
                for k in range(n if lin else 0):
                    for l in range(k, n):
                        for w in range(W):
                            PP[j, k, l, w] = 0.0
                # (F P Fᵀ)[k, r] = Σ_e F[r, c_e] (F P)[k, c_e], upper triangle k ≤ r
                for e in range(Fnnz[j] if lin else 0):
                    r = Fr[j, e]
                    c = Fc[j, e]
                    v = Fv[j, e]
                    for k in range(r + 1):
                        for w in range(W):
                            PP[j, k, r, w] += FP[k, c, w] * v
                for k in range(n if lin else 0):
                    for l in range(k, n):
                        q = Q[j, k, l]
                        for w in range(W):
                            PP[j, k, l, w] += q
                    for l in range(k):
                        for w in range(W):
                            PP[j, k, l, w] = PP[j, l, k, w]

                # ---- Step 3b: ẑ_j = H x_j, P_j Hᵀ, S_j = H P_j Hᵀ + R, over the non-zeros of H
                for a in range(m):
                    for w in range(W):
                        zh[j, a, w] = 0.0
                    for k in range(n):
                        for w in range(W):
                            PHt[j, k, a, w] = 0.0
                for e in range(nH):
                    a = Hr[e]
                    c = Hc[e]
                    v = Hv[e]
                    for w in range(W):
                        zh[j, a, w] += v * XP[j, c, w]
                    for k in range(n):
                        for w in range(W):
                            PHt[j, k, a, w] += PP[j, k, c, w] * v
                for a in range(m):
                    for a2 in range(a, m):
                        rr = R[a, a2]
                        for w in range(W):
                            S[j, a, a2, w] = rr
                for e in range(nH):
                    a = Hr[e]
                    c = Hc[e]
                    v = Hv[e]
                    for a2 in range(a, m):
                        for w in range(W):
                            S[j, a, a2, w] += v * PHt[j, c, a2, w]
                for a in range(m):
                    for a2 in range(a):
                        for w in range(W):
                            S[j, a, a2, w] = S[j, a2, a, w]
                _inv_logdet(S[j], Si[j], logdet[j], L, Li, True)
                # innovation ν_j = z − ẑ_j, d²_j = ν_jᵀ S_j⁻¹ ν_j, log N(z; ẑ_j, S_j)
                for a in range(m):
                    for w in range(W):
                        nu[j, a, w] = zc[a, w] - zh[j, a, w]
                for w in range(W):
                    d2[j, w] = 0.0
                for a in range(m):
                    for a2 in range(m):
                        for w in range(W):
                            d2[j, w] += nu[j, a, w] * Si[j, a, a2, w] * nu[j, a2, w]
                for w in range(W):
                    # S_j not positive definite (NaN log det) or d² overflowing: the mode
                    # explains nothing (NaN d² fails every comparison below)
                    ok = logdet[j, w] == logdet[j, w] and d2[j, w] < np.inf
                    d2[j, w] = d2[j, w] if ok else np.nan
                    ll[j, w] = -0.5 * (d2[j, w] + logdet[j, w]) - half_m_log2pi

            # ---- gate: the measurement is used unless no reachable mode explains it
            for w in range(W):
                g = True
                for j in range(M):
                    if d2[j, w] <= gate_d2 and cbar[j, w] > 0.0:
                        g = False
                use[w] = have[w] and not g
                if live[w]:
                    gated_o[b0 + w] = have[w] and g

            # ---- mixture innovation NIS with the predicted mode probabilities c̄
            for a in range(m):
                for w in range(W):
                    zbar[a, w] = 0.0
                for j in range(M):
                    for w in range(W):
                        zbar[a, w] += cbar[j, w] * zh[j, a, w]
            for a in range(m):
                for a2 in range(a, m):
                    for w in range(W):
                        Sbar[a, a2, w] = 0.0
            for j in range(M):
                for a in range(m):
                    for a2 in range(a, m):
                        for w in range(W):
                            Sbar[a, a2, w] += cbar[j, w] * (
                                S[j, a, a2, w]
                                + (zh[j, a, w] - zbar[a, w]) * (zh[j, a2, w] - zbar[a2, w])
                            )
            for a in range(m):
                for a2 in range(a):
                    for w in range(W):
                        Sbar[a, a2, w] = Sbar[a2, a, w]
                for w in range(W):
                    dz[a, w] = zc[a, w] - zbar[a, w]
            _inv_logdet(Sbar, Sbi, ldb, L, Li, False)
            for w in range(W):
                nis[w] = 0.0
            for a in range(m):
                for a2 in range(m):
                    for w in range(W):
                        nis[w] += dz[a, w] * Sbi[a, a2, w] * dz[a2, w]

            # ---- Step 3c: mode-matched update where the measurement is used:
            #      K = P Hᵀ S⁻¹, x += K ν, Joseph form P = (I − K H) P (I − K H)ᵀ + K R Kᵀ
            for j in range(M):
                for k in range(n):
                    for a in range(m):
                        for w in range(W):
                            K[k, a, w] = 0.0
                        for a2 in range(m):
                            for w in range(W):
                                K[k, a, w] += PHt[j, k, a2, w] * Si[j, a2, a, w]
                # (the tracker loop w is innermost everywhere, so that it vectorises)
                for k in range(n):
                    for w in range(W):
                        tmp[w] = 0.0
                    for a in range(m):
                        for w in range(W):
                            tmp[w] += K[k, a, w] * nu[j, a, w]
                    for w in range(W):
                        XP[j, k, w] = XP[j, k, w] + tmp[w] if use[w] else XP[j, k, w]
                # (I − K H) P = P − K (H P), with H P = (P Hᵀ)ᵀ as P is symmetric
                for k in range(n):
                    for l in range(n):
                        for w in range(W):
                            AP[k, l, w] = PP[j, k, l, w]
                        for a in range(m):
                            for w in range(W):
                                AP[k, l, w] -= K[k, a, w] * PHt[j, l, a, w]
                # G = K R − ((I − K H) P) Hᵀ; then P = (I − K H) P + G Kᵀ, which is
                # (I − K H) P (I − K H)ᵀ + K R Kᵀ
                for k in range(n):
                    for a in range(m):
                        for w in range(W):
                            G[k, a, w] = 0.0
                for e in range(nH):
                    a = Hr[e]
                    c = Hc[e]
                    v = Hv[e]
                    for k in range(n):
                        for w in range(W):
                            G[k, a, w] -= AP[k, c, w] * v
                for k in range(n):
                    for a in range(m):
                        for a2 in range(m):
                            rr = R[a2, a]
                            for w in range(W):
                                G[k, a, w] += K[k, a2, w] * rr
                for k in range(n):
                    for l in range(k, n):
                        for w in range(W):
                            tmp[w] = AP[k, l, w]
                        for a in range(m):
                            for w in range(W):
                                tmp[w] += G[k, a, w] * K[l, a, w]
                        for w in range(W):
                            PP[j, k, l, w] = tmp[w] if use[w] else PP[j, k, l, w]
                    for l in range(k):
                        for w in range(W):
                            PP[j, k, l, w] = PP[j, l, k, w]

            # ---- Step 4: mode probabilities μ_j = c̄_j Λ_j / Σ_l c̄_l Λ_l, with the likelihoods
            #      scaled by the largest one, exp(log Λ_j − max_l log Λ_l), so none underflows
            #      unless it is negligible; c̄ where the measurement is missing or gated.
            for w in range(W):
                if use[w]:
                    mx = -np.inf
                    for j in range(M):
                        if cbar[j, w] > 0.0 and ll[j, w] > mx:
                            mx = ll[j, w]
                    s = 0.0
                    for j in range(M):
                        c = cbar[j, w]
                        # a mode with a NaN likelihood (see above) gets no weight
                        e = c * math.exp(ll[j, w] - mx) if (c > 0.0 and ll[j, w] > -np.inf) else 0.0
                        mun[j, w] = e
                        s += e
                    for j in range(M):
                        mun[j, w] = mun[j, w] / s
                else:
                    for j in range(M):
                        mun[j, w] = cbar[j, w]

            # ---- Step 5: combination x = Σ_j μ_j x_j, P = Σ_j μ_j [P_j + (x_j − x)(x_j − x)ᵀ]
            for k in range(n):
                for w in range(W):
                    xc[k, w] = 0.0
                for j in range(M):
                    for w in range(W):
                        xc[k, w] += XP[j, k, w] * mun[j, w]
            for k in range(n):
                for l in range(k, n):
                    for w in range(W):
                        Pc[k, l, w] = 0.0
            for j in range(M):
                for k in range(n):
                    for w in range(W):
                        D[k, w] = XP[j, k, w] - xc[k, w]
                for k in range(n):
                    for l in range(k, n):
                        for w in range(W):
                            Pc[k, l, w] += mun[j, w] * (D[k, w] * D[l, w] + PP[j, k, l, w])

            # ---- the new state of the live lanes (free lanes keep theirs)
            if nl == W:
                X[:] = XP
                Pin[:] = PP
                mu_c[:] = mun
            else:
                for w in range(W):
                    if live[w]:
                        for j in range(M):
                            mu_c[j, w] = mun[j, w]
                            for k in range(n):
                                X[j, k, w] = XP[j, k, w]
                                for l in range(n):
                                    Pin[j, k, l, w] = PP[j, k, l, w]
            # ---- scatter the chunk
            for w in range(W):
                if not live[w]:
                    continue
                b = b0 + w
                nis_o[b] = nis[w] if have[w] else np.nan
                for j in range(M):
                    mu_o[b, j] = mun[j, w]
                    ll_o[b, j] = ll[j, w] if have[w] else np.nan
                for k in range(n):
                    x_o[b, k] = xc[k, w]
                    for l in range(n):
                        P_o[b, k, l] = Pc[k, l, w] if l >= k else Pc[l, k, w]

    return imm_step


_STEP_KERNEL = []


def imm_step_kernel():
    """The IMM step kernel: one for every model size (the sizes are read from the arrays
    at run time; only the chunk width :data:`CHUNK` is fixed), compiled once."""
    if not _STEP_KERNEL:
        _STEP_KERNEL.append(_make_imm_step(CHUNK))
    return _STEP_KERNEL[0]


@njit(cache=True, error_model="numpy")
def predict_modes(F, Q, U, xm, Pm, steps, xs, Ps):
    """Each mode's own model propagated 1..steps steps ahead (no mixing).

    xm (B, M, n), Pm (B, M, n, n) in; xs (B, M, steps, n), Ps (B, M, steps, n, n) out.
    """
    B = xm.shape[0]
    M = xm.shape[1]
    n = xm.shape[2]
    x = np.empty(n)
    P = np.empty((n, n))
    FP = np.empty((n, n))
    for b in range(B):
        for j in range(M):
            for k in range(n):
                x[k] = xm[b, j, k]
                for l in range(n):
                    P[k, l] = Pm[b, j, k, l]
            for t in range(steps):
                for k in range(n):
                    s = U[j, k]
                    for l in range(n):
                        s += F[j, k, l] * x[l]
                    xs[b, j, t, k] = s
                    for l in range(n):
                        s = 0.0
                        for i in range(n):
                            s += F[j, k, i] * P[i, l]
                        FP[k, l] = s
                for k in range(n):
                    for l in range(k, n):
                        s = 0.0
                        for i in range(n):
                            s += FP[k, i] * F[j, l, i]
                        s += Q[j, k, l]
                        Ps[b, j, t, k, l] = s
                        Ps[b, j, t, l, k] = s
                for k in range(n):
                    x[k] = xs[b, j, t, k]
                    for l in range(n):
                        P[k, l] = Ps[b, j, t, k, l]
