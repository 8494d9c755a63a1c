"""Numba kernels of the batched IMM (paper §IV). Internal: use :class:`airspace_sim.tracking.IMM`.

One call of :func:`imm_step` runs one IMM cycle for every tracker of the batch, in a single
loop over trackers with small fixed-size inner loops over modes and state components. All
work arrays are allocated once per call, outside the tracker loop. There is no ``fastmath``
and no parallel reduction, so a tracker's result depends only on its own inputs: the same
bits whatever the batch it is in and whichever run.

Shapes: ``B`` trackers, ``M`` modes, ``n`` states, ``m`` measurement components.

Transition matrices are passed as a dense ``(M, n, n)`` array *and* as a per-mode list of
their non-zero entries (row-major, ``nnz`` entries each, padded): the coordinated-turn
matrices are mostly zeros, and ``F P Fᵀ`` only over the non-zeros is 2–3× cheaper. The
measurement matrix is handled the same way.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_LOG_2PI = math.log(2.0 * math.pi)


@njit(cache=True)
def _inv_logdet(S, Si, L, Li, m):
    """Inverse ``Si`` and ``log det`` of the symmetric positive definite ``S`` (m, m).

    Closed form for m = 1, 2; Cholesky otherwise (``L``, ``Li`` are (m, m) work arrays).
    Returns ``log det S``, or NaN if ``S`` is not positive definite.
    """
    if m == 1:
        s = S[0, 0]
        if not (s > 0.0):
            return np.nan
        Si[0, 0] = 1.0 / s
        return math.log(s)
    if m == 2:
        a = S[0, 0]
        b = S[0, 1]
        d = S[1, 1]
        det = a * d - b * b
        if not (det > 0.0 and a > 0.0):
            return np.nan
        Si[0, 0] = d / det
        Si[0, 1] = -b / det
        Si[1, 0] = -b / det
        Si[1, 1] = a / det
        return math.log(det)
    # Cholesky S = L Lᵀ
    logdet = 0.0
    for i in range(m):
        for j in range(i + 1):
            s = S[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not (s > 0.0):
                    return np.nan
                L[i, i] = math.sqrt(s)
                logdet += 2.0 * math.log(L[i, i])
            else:
                L[i, j] = s / L[j, j]
        for j in range(i + 1, m):
            L[i, j] = 0.0
    # Li = L⁻¹ (lower triangular)
    for i in range(m):
        for j in range(m):
            Li[i, j] = 0.0
    for i in range(m):
        Li[i, i] = 1.0 / L[i, i]
        for j in range(i):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * Li[k, j]
            Li[i, j] = s / L[i, i]
    # Si = Liᵀ Li (symmetric)
    for i in range(m):
        for j in range(i, m):
            s = 0.0
            for k in range(j, m):
                s += Li[k, i] * Li[k, j]
            Si[i, j] = s
            Si[j, i] = s
    return logdet


@njit(cache=True)
def imm_step(
    F, Fr, Fc, Fv, Fnnz, Q, U, H, Hr, Hc, Hv, R, Pi, gate_d2,
    z, xm, Pm, mu,
    xm_o, Pm_o, mu_o, x_o, P_o, nis_o, ll_o, gated_o,
):  # fmt: skip
    """One IMM cycle (paper §IV, steps 1–5) for every tracker.

    Model
    -----
    F (M, n, n), Q (M, n, n) symmetric, U (M, n) offsets, H (m, n), R (m, m) symmetric PD,
    Pi (M, M) row-stochastic, gate_d2 scalar (chi-square gate on d², ``inf`` = no gate).
    Fr, Fc, Fv (M, K): row, column, value of the non-zeros of each F[j] (first Fnnz[j]).
    Hr, Hc, Hv (KH,): the non-zeros of H.

    State in (read only): z (B, m), xm (B, M, n), Pm (B, M, n, n), mu (B, M).
    State out (written): xm_o, Pm_o, mu_o, x_o (B, n), P_o (B, n, n), nis_o (B,),
    ll_o (B, M), gated_o (B,) bool. Outputs must not alias inputs.
    """
    B = xm.shape[0]
    M = xm.shape[1]
    n = xm.shape[2]
    m = H.shape[0]
    nH = Hr.shape[0]

    cbar = np.empty(M)
    logc = np.empty(M)
    om = np.empty((M, M))
    x0 = np.empty(n)
    P0 = np.empty((n, n))
    d = np.empty(n)
    FP = np.empty((n, n))
    zh = np.empty((M, m))
    nu = np.empty((M, m))
    S = np.empty((M, m, m))
    Si = np.empty((M, m, m))
    PHt = np.empty((M, n, m))
    d2 = np.empty(M)
    lw = np.empty(M)
    K = np.empty((n, m))
    A = np.empty((n, n))
    AP = np.empty((n, n))
    KR = np.empty((n, m))
    L = np.empty((m, m))
    Li = np.empty((m, m))
    zbar = np.empty(m)
    Sbar = np.empty((m, m))
    Sbi = np.empty((m, m))
    dz = np.empty(m)
    half_m_log2pi = 0.5 * m * _LOG_2PI

    for b in range(B):
        # ---- Step 1: mixing probabilities  μ_{i|j} = π_ij μ_i / c̄_j,  c̄_j = Σ_i π_ij μ_i
        for j in range(M):
            s = 0.0
            for i in range(M):
                s += Pi[i, j] * mu[b, i]
            cbar[j] = s
        for j in range(M):
            if cbar[j] > 0.0:
                for i in range(M):
                    om[i, j] = (Pi[i, j] * mu[b, i]) / cbar[j]
            else:  # mode j unreachable: keep its own estimate (its μ stays 0)
                for i in range(M):
                    om[i, j] = 1.0 if i == j else 0.0

        for j in range(M):
            # ---- Step 2: mixed initial condition x0j = Σ_i μ_{i|j} x_i,
            #      P0j = Σ_i μ_{i|j} (P_i + (x_i − x0j)(x_i − x0j)ᵀ)
            for k in range(n):
                s = 0.0
                for i in range(M):
                    s += xm[b, i, k] * om[i, j]
                x0[k] = s
            for k in range(n):
                for l in range(k, n):
                    P0[k, l] = 0.0
            for i in range(M):
                w = om[i, j]
                if w == 0.0:
                    continue
                for k in range(n):
                    d[k] = xm[b, i, k] - x0[k]
                for k in range(n):
                    for l in range(k, n):
                        P0[k, l] += w * (d[k] * d[l] + Pm[b, i, k, l])
            for k in range(n):
                for l in range(k):
                    P0[k, l] = P0[l, k]

            # ---- Step 3a: mode-matched prediction  x = F_j x0j + u_j,  P = F_j P0j F_jᵀ + Q_j
            for k in range(n):
                xm_o[b, j, k] = U[j, k]
                for l in range(n):
                    FP[k, l] = 0.0
            for e in range(Fnnz[j]):
                r = Fr[j, e]
                c = Fc[j, e]
                v = Fv[j, e]
                xm_o[b, j, r] += v * x0[c]
                for l in range(n):
                    FP[r, l] += v * P0[c, l]
            for k in range(n):
                for l in range(k, n):
                    Pm_o[b, j, k, l] = 0.0
            # (F P Fᵀ)[k, l] = Σ_e F[l, c_e] FP[k, c_e] over non-zeros (l = r_e), upper triangle
            for e in range(Fnnz[j]):
                r = Fr[j, e]
                c = Fc[j, e]
                v = Fv[j, e]
                for k in range(r + 1):
                    Pm_o[b, j, k, r] += FP[k, c] * v
            for k in range(n):
                for l in range(k, n):
                    Pm_o[b, j, k, l] += Q[j, k, l]
                for l in range(k):
                    Pm_o[b, j, k, l] = Pm_o[b, j, l, k]

        have_z = True
        for a in range(m):
            if not math.isfinite(z[b, a]):
                have_z = False
        gated = False
        if have_z:
            # ---- Step 3b: innovations, S_j = H P_j Hᵀ + R, d²_j, log N(z; ẑ_j, S_j)
            all_out = True
            for j in range(M):
                for k in range(n):
                    for a in range(m):
                        PHt[j, k, a] = 0.0
                for a in range(m):
                    zh[j, a] = 0.0
                for e in range(nH):
                    a = Hr[e]
                    c = Hc[e]
                    v = Hv[e]
                    zh[j, a] += v * xm_o[b, j, c]
                    for k in range(n):
                        PHt[j, k, a] += Pm_o[b, j, k, c] * v
                for a in range(m):
                    for a2 in range(a, m):
                        S[j, a, a2] = R[a, a2]
                for e in range(nH):
                    a = Hr[e]
                    c = Hc[e]
                    v = Hv[e]
                    for a2 in range(a, m):
                        S[j, a, a2] += v * PHt[j, c, a2]
                for a in range(m):
                    for a2 in range(a):
                        S[j, a, a2] = S[j, a2, a]
                logdet = _inv_logdet(S[j], Si[j], L, Li, m)
                for a in range(m):
                    nu[j, a] = z[b, a] - zh[j, a]
                q = 0.0
                for a in range(m):
                    s = 0.0
                    for a2 in range(m):
                        s += Si[j, a, a2] * nu[j, a2]
                    q += nu[j, a] * s
                d2[j] = q
                ll_o[b, j] = -0.5 * (q + logdet) - half_m_log2pi
                # gated unless some reachable mode (c̄_j > 0) explains z (NaN d² explains nothing)
                if q <= gate_d2 and cbar[j] > 0.0:
                    all_out = False
            gated = all_out
            # mixture (moment-matched) innovation NIS with the predicted mode probabilities c̄
            for a in range(m):
                s = 0.0
                for j in range(M):
                    s += cbar[j] * zh[j, a]
                zbar[a] = s
            for a in range(m):
                for a2 in range(a, m):
                    Sbar[a, a2] = 0.0
            for j in range(M):
                for a in range(m):
                    dz[a] = zh[j, a] - zbar[a]
                for a in range(m):
                    for a2 in range(a, m):
                        Sbar[a, a2] += cbar[j] * (S[j, a, a2] + dz[a] * dz[a2])
            for a in range(m):
                for a2 in range(a):
                    Sbar[a, a2] = Sbar[a2, a]
                dz[a] = z[b, a] - zbar[a]
            _inv_logdet(Sbar, Sbi, L, Li, m)
            q = 0.0
            for a in range(m):
                s = 0.0
                for a2 in range(m):
                    s += Sbi[a, a2] * dz[a2]
                q += dz[a] * s
            nis_o[b] = q
        else:
            for j in range(M):
                ll_o[b, j] = np.nan
            nis_o[b] = np.nan
        gated_o[b] = gated

        if have_z and not gated:
            for j in range(M):
                # ---- Step 3c: mode-matched update, K = P Hᵀ S⁻¹, x += K ν,
                #      Joseph form P = (I − K H) P (I − K H)ᵀ + K R Kᵀ, symmetrised
                for k in range(n):
                    for a in range(m):
                        s = 0.0
                        for a2 in range(m):
                            s += PHt[j, k, a2] * Si[j, a2, a]
                        K[k, a] = s
                for k in range(n):
                    s = 0.0
                    for a in range(m):
                        s += K[k, a] * nu[j, a]
                    xm_o[b, j, k] += s
                for k in range(n):
                    for l in range(n):
                        A[k, l] = 1.0 if k == l else 0.0
                for e in range(nH):
                    a = Hr[e]
                    c = Hc[e]
                    v = Hv[e]
                    for k in range(n):
                        A[k, c] -= K[k, a] * v
                for k in range(n):
                    for l in range(n):
                        s = 0.0
                        for i in range(n):
                            s += A[k, i] * Pm_o[b, j, i, l]
                        AP[k, l] = s
                for k in range(n):
                    for a in range(m):
                        s = 0.0
                        for a2 in range(m):
                            s += K[k, a2] * R[a2, a]
                        KR[k, a] = s
                for k in range(n):
                    for l in range(k, n):
                        s = 0.0
                        for i in range(n):
                            s += AP[k, i] * A[l, i]
                        t = 0.0
                        for a in range(m):
                            t += KR[k, a] * K[l, a]
                        Pm_o[b, j, k, l] = s + t
                for k in range(n):
                    for l in range(k):
                        Pm_o[b, j, k, l] = Pm_o[b, j, l, k]
            # ---- Step 4: mode probabilities μ_j ∝ Λ_j c̄_j, in log space (log-sum-exp)
            mx = -np.inf
            for j in range(M):
                if cbar[j] > 0.0:
                    lw[j] = ll_o[b, j] + math.log(cbar[j])
                else:
                    lw[j] = -np.inf
                if lw[j] > mx:
                    mx = lw[j]
            s = 0.0
            for j in range(M):
                s += math.exp(lw[j] - mx)
            lse = mx + math.log(s)
            for j in range(M):
                mu_o[b, j] = math.exp(lw[j] - lse)
        else:
            # no (usable) measurement: predict only, μ = c̄
            for j in range(M):
                mu_o[b, j] = cbar[j]

        # ---- Step 5: combination x = Σ_j μ_j x_j,  P = Σ_j μ_j (P_j + (x_j − x)(x_j − x)ᵀ)
        for k in range(n):
            s = 0.0
            for j in range(M):
                s += xm_o[b, j, k] * mu_o[b, j]
            x_o[b, k] = s
        for k in range(n):
            for l in range(k, n):
                P_o[b, k, l] = 0.0
        for j in range(M):
            w = mu_o[b, j]
            if w == 0.0:
                continue
            for k in range(n):
                d[k] = xm_o[b, j, k] - x_o[b, k]
            for k in range(n):
                for l in range(k, n):
                    P_o[b, k, l] += w * (d[k] * d[l] + Pm_o[b, j, k, l])
        for k in range(n):
            for l in range(k):
                P_o[b, k, l] = P_o[b, l, k]


@njit(cache=True)
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
