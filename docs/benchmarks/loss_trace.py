"""Every loss of separation of one run, pair by pair: what each aircraft was doing before it,
and what the CDA policy's resume check predicted about the other when it let a turn back
through.

    python docs/benchmarks/loss_trace.py ring:100:0 bands --policy 'resume_rule="no-worse"'
    python docs/benchmarks/loss_trace.py dense:2 bands --window 90

Arguments: a case (``ring:N:SEED`` or ``dense:SEED``, as in resolver_candidates.py, one seed)
and a resolver kind (``kind:key=value``). For each pair that enters loss of separation
(true positions, distance < r_safe) it prints, for both aircraft A and B:

- the timeline of their CDA state over the last ``--window`` s, as runs
  ``[from..to s] STATE turn`` with STATE ``route`` (autopilot, no turn back pending),
  ``avoid`` (in conflict, flying the advice), ``hold`` (turn back refused), ``part``
  (a fraction of the turn back), ``back`` (the whole turn back) and the mean true turn
  rate of the run (deg/s, + left);
- the resolver's advice on every step the aircraft was alerted, as runs ``[from..to s] psi
  first->last deg side S clear|boxed ratio R by WHO (R_WHO)``: the target heading change
  (the step flies at most the turn limit of it), the committed side after the step,
  ``clear`` when a candidate on either side was clear (``boxed``: none), the resolver's
  minimum ratio at the target (as flown for ``bands-flown``), and the intruder nearest to
  the clear radius at the target judged at once (``B``: the other of the pair) with its
  ratio; so ``side -1 clear ratio 0.6`` is an ownship committed right whose right side had
  no clear heading while the left had one;
- every resume decision in the window that let a turn back through (fraction > 0) while the
  other aircraft was one of its confirmed tracks within 2·R1: the fraction, the straight-line
  minimum distance to the other the rule predicted for that fraction and for holding, the
  IMM mode probabilities of the other's track (straight, left, right), the other's state
  and true turn rate then, and the true minimum distance the pair then reached.

Then the metrics. Losses are numbered in the order they begin.

``--oracle`` adds, per loss, whether it was avoidable at all by one aircraft: from the first
detection (the start of the last unbroken run of steps, within the window, in which A's or
B's track of the other predicts a straight-line miss under r_safe·(1 + margin) within the
look-ahead; "≥ window" if it covers the whole window), can A alone, or B alone, turning at
its turn limit to either side for τ ∈ {0, 1, …, 180} s and then flying straight, keep
r_safe from the other, the other flying its actual recorded path (column "actual") or
straight from its state at the detection (column "straight"), up to 60 s after the loss
began. Pairwise: third aircraft are ignored.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from resolver_candidates import scenario  # noqa: E402

from airspace_sim.avoidance.cpa import cpa_pair_ratios  # noqa: E402
from airspace_sim.world import World  # noqa: E402
from airspace_sim.world.bodies import LOS  # noqa: E402
from airspace_sim.world.policy import TURN_TOLERANCE  # noqa: E402

STATES = ("route", "avoid", "hold", "part", "back")


class Recorder:
    """Wraps a World's policy: per step the CDA state of every aircraft, and the resume
    decisions with the per-intruder predictions behind them (a rolling window)."""

    def __init__(self, world: World, window_steps: int):
        self.w = world
        pol = world.policy
        self.window = window_steps
        self.states = collections.deque(maxlen=window_steps)  # (N,) int per step
        self.turns = collections.deque(maxlen=window_steps)  # (N,) rad per step
        self.times = collections.deque(maxlen=window_steps)
        self.decisions = collections.deque(maxlen=window_steps)  # {owner: (frac, {j: ...})}
        self.truth = collections.deque(maxlen=window_steps)  # ((N, 2) m, (N, 2) m/s)
        self.tracked = collections.deque(maxlen=window_steps)  # (Encounters, intruder ids)
        self._decided = {}
        self._orig_fraction = pol._resume_fraction
        self._orig_clear = pol._resume_clear
        self._orig_override = pol.override
        pol._resume_fraction = self._fraction
        pol._resume_clear = self._clear
        pol.override = self._override
        # the resolver's advice per alerted aircraft (advise: prefilter, resolve, commit)
        self.advice = collections.deque(maxlen=window_steps)  # (t, {owner: AdviceRow})
        self._orig_advise, self._orig_prefilter = pol.advise, pol._prefilter
        self._orig_resolve, self._orig_commit = pol.resolver.resolve, pol._commit
        self._step_enc = self._step_out = self._step_psi = None
        pol.advise, pol._prefilter, pol._commit = self._advise, self._prefilter, self._commit
        pol.resolver.resolve = self._resolve

    def _prefilter(self, enc, velocities):
        self._step_enc = self._orig_prefilter(enc, velocities)
        return self._step_enc

    def _resolve(self, *args, **kwargs):
        self._step_out = self._orig_resolve(*args, **kwargs)
        return self._step_out

    def _commit(self, *args, **kwargs):
        out = self._orig_commit(*args, **kwargs)
        self._step_psi = out
        return out

    def _advise(self, tracks, positions, velocities, active, max_heading_change):
        """The policy's advise, recording for every alerted ownship: the target heading
        change (rad; the step flies at most the turn limit of it), its minimum ratio as the resolver judged it (``min_ratio``: at once
        for ``bands``, as flown for ``bands-flown``), whether any candidate was clear, the
        committed side, and the intruder (world index) nearest to the clear radius at the
        target heading judged at once, with that pair's ratio."""
        self._step_enc = self._step_out = self._step_psi = None
        pol = self.w.policy
        t = self.w.time
        advice, conflict = self._orig_advise(
            tracks, positions, velocities, active, max_heading_change
        )
        rows = {}
        enc, out = self._step_enc, self._step_out
        if enc is None:
            enc = pol._encounters
        if out is not None and enc.owners.size == np.asarray(out.conflict).size:
            view = tracks.view()
            psi = np.asarray(out.heading_change, dtype=float)
            if self._step_psi is not None:
                psi = np.asarray(self._step_psi[0], dtype=float)
            vo = velocities[enc.owners]
            pair = cpa_pair_ratios(
                vo,
                enc.rel_position,
                enc.rel_velocity,
                enc.valid,
                psi[:, None],
                pol.r_safe * (1.0 + pol.margin),
                pol.lookahead_s,
            )[:, :, 0]
            cand = None if out.candidates is None else np.asarray(out.candidates)
            ratio = None if out.min_ratio is None else np.asarray(out.min_ratio)
            for i, o in enumerate(enc.owners.tolist()):
                if not out.conflict[i]:
                    continue
                k = int(np.argmin(np.where(enc.valid[i], pair[i], np.inf)))
                who = int(view.intruder[enc.rows[i, k]]) if enc.valid[i, k] else -1
                r_choice, any_clear = float("nan"), False
                if cand is not None and ratio is not None:
                    near = np.nanargmin(np.abs(cand[i] - psi[i]))
                    r_choice = float(ratio[i, near])
                    any_clear = bool((np.asarray(out.first_clear)[i, :2] >= 0).any())
                rows[o] = (
                    float(psi[i]),
                    r_choice,
                    any_clear,
                    float(pol.side[o]),
                    who,
                    float(pair[i, k]),
                )
        self.advice.append((t, rows))
        return advice, conflict

    def _predictions(self, enc, velocities, psi_row):
        """{owner: {intruder: (pred m at psi, pred m holding, mu, |r| m)}} for enc."""
        pol, view = self.w.policy, self.w.tracks.view()
        n, k = enc.valid.shape
        if not n or not k:
            return {}
        vo = velocities[enc.owners]
        psi = np.stack([psi_row, np.zeros(n)], axis=1)
        pair = cpa_pair_ratios(
            vo, enc.rel_position, enc.rel_velocity, enc.valid, psi, 1.0, pol.lookahead_s
        )
        r1 = pol.r_safe * (1.0 + pol.margin + pol.resume_margin)
        out = {}
        for a in range(n):
            row = {}
            for b in range(k):
                if not enc.valid[a, b] or pair[a, b, 1] > 2 * r1:
                    continue
                t = enc.rows[a, b]
                row[int(view.intruder[t])] = (
                    float(pair[a, b, 0]),
                    float(pair[a, b, 1]),
                    tuple(np.round(view.mu[t], 2)),
                    float(np.hypot(*enc.rel_position[a, b])),
                )
            out[int(enc.owners[a])] = row
        return out

    def _fraction(self, enc, velocities, turn, max_heading_change, desired=None):
        frac = self._orig_fraction(enc, velocities, turn, max_heading_change, desired)
        mx = max_heading_change[enc.owners]
        psi = np.clip(turn, -mx, mx) * frac
        pred = self._predictions(enc, velocities, psi)
        for o, f in zip(enc.owners.tolist(), frac.tolist(), strict=True):
            self._decided[o] = (f, pred.get(o, {}))
        return frac

    def _clear(self, enc, velocities, turn, max_heading_change):
        clear = self._orig_clear(enc, velocities, turn, max_heading_change)
        mx = max_heading_change[enc.owners]
        frac = np.where(clear, 1.0, 0.0)
        pred = self._predictions(enc, velocities, np.clip(turn, -mx, mx) * frac)
        for o, f in zip(enc.owners.tolist(), frac.tolist(), strict=True):
            self._decided[o] = (f, pred.get(o, {}))
        return clear

    def _override(self, rate, desired, active, velocities, max_heading_change, avoid=None):
        pol = self.w.policy
        conflict = pol.conflict.copy()
        self._decided = {}
        out = self._orig_override(rate, desired, active, velocities, max_heading_change, avoid)
        flying = (pol.avoid if avoid is None else avoid) & active
        resuming = (
            flying & ~conflict & np.isfinite(desired) & (np.abs(rate) * pol.dt > TURN_TOLERANCE)
        )
        state = np.zeros(rate.size, dtype=np.int64)
        state[resuming] = 4
        for o, (f, _) in self._decided.items():
            state[o] = 2 if f == 0.0 else (3 if f < 1.0 else 4)
        state[flying & conflict] = 1
        self.states.append(state)
        self.turns.append(np.clip(out, -self.w.max_turn_rate, self.w.max_turn_rate) * pol.dt)
        self.times.append(self.w.time)
        self.decisions.append(self._decided)
        self.truth.append((self.w.positions.copy(), velocities.copy()))
        enc = pol._encounters
        view = self.w.tracks.view()
        self.tracked.append((enc, np.where(enc.valid, view.intruder[np.maximum(enc.rows, 0)], -1)))
        return out

    def straight_miss(self, i: int, a: int, b: int) -> tuple[float, float, float, float]:
        """At window step i: the true distance of a and b, m; the minimum distance over the
        look-ahead with both flying straight, from true states and from a's and b's tracks
        of each other (NaN: no confirmed track), m."""
        pos, vel = self.truth[i]
        T = self.w.policy.lookahead_s

        def miss(r, v):
            t = np.clip(-np.dot(r, v) / max(np.dot(v, v), 1e-300), 0.0, T)
            return float(np.hypot(*(r + t * v)))

        out = [float(np.hypot(*(pos[b] - pos[a]))), miss(pos[b] - pos[a], vel[b] - vel[a])]
        enc, intruder = self.tracked[i]
        for o, j in ((a, b), (b, a)):
            row = np.flatnonzero(enc.owners == o)
            slot = np.flatnonzero(intruder[row[0]] == j) if row.size else row
            out.append(
                miss(enc.rel_position[row[0], slot[0]], enc.rel_velocity[row[0], slot[0]])
                if slot.size
                else float("nan")
            )
        return tuple(out)


def timeline(rec: Recorder, a: int, t_loss: float) -> str:
    """Runs of aircraft a's state over the window, times relative to the loss."""
    st = [int(s[a]) for s in rec.states]
    tu = [float(u[a]) for u in rec.turns]
    ts = list(rec.times)
    runs, i = [], 0
    while i < len(st):
        j = i
        while j + 1 < len(st) and st[j + 1] == st[i]:
            j += 1
        rate = np.degrees(np.mean(tu[i : j + 1])) / rec.w.dt
        runs.append(f"[{ts[i] - t_loss:+.0f}..{ts[j] - t_loss:+.0f}] {STATES[st[i]]} {rate:+.1f}")
        i = j + 1
    return "; ".join(runs)


def advice_runs(rec: Recorder, a: int, b: int, t_loss: float) -> str:
    """Runs of aircraft a's alerted steps over the window: ``[from..to s] ψ from→to deg,
    side, clear (a candidate clear on either side) or boxed, min ratio of the target
    heading (the resolver's judgement), binding intruder (``B``: the other of the pair) and
    its at-once ratio at the target heading``; times relative to the loss."""
    runs, cur = [], None
    for t, rows in rec.advice:
        if a not in rows:
            cur = None
            continue
        psi, ratio, clear, side, who, r_who = rows[a]
        key = (clear, side, "B" if who == b else str(who))
        if cur is not None and cur[0] == key and t - cur[2] <= rec.w.dt * 1.5:
            cur[2], cur[4], cur[6] = t, psi, min(cur[6], ratio)
            cur[7] = min(cur[7], r_who)
            continue
        cur = [key, t, t, psi, psi, side, ratio, r_who]
        runs.append(cur)
    out = []
    for key, t0, t1, p0, p1, side, ratio, r_who in runs:
        clear, _, who = key
        out.append(
            f"[{t0 - t_loss:+.0f}..{t1 - t_loss:+.0f}] psi {np.degrees(p0):+.0f}->"
            f"{np.degrees(p1):+.0f} side {side:+.0f} {'clear' if clear else 'boxed'} "
            f"ratio {ratio:.2f} by {who} ({r_who:.2f})"
        )
    return "; ".join(out) if out else "(not alerted)"


def one_turn_avoids(p0, h0, speed, max_rate, other, dt, r_safe, max_tau_s=180.0) -> bool:
    """Can an aircraft at p0 (m), heading h0 (rad), speed (m/s) keep more than r_safe (m)
    from ``other`` (S, 2) m (positions every dt s from now) by turning at ±max_rate (rad/s)
    for some tau in {0, dt, …, max_tau_s} s and then flying straight? Closed-form arcs."""
    t = np.arange(other.shape[0]) * dt  # (S,) s
    taus = np.arange(0.0, max_tau_s + dt / 2, dt)[:, None]  # (T, 1) s
    for w in (max_rate, -max_rate):
        tt = np.minimum(t[None, :], taus)  # time spent turning
        h = h0 + w * tt
        # position after turning for tt: the arc, then straight for t - tt
        ax = p0[0] + speed / w * (np.sin(h) - np.sin(h0))
        ay = p0[1] - speed / w * (np.cos(h) - np.cos(h0))
        x = ax + speed * np.cos(h) * (t[None, :] - tt)
        y = ay + speed * np.sin(h) * (t[None, :] - tt)
        d = np.hypot(x - other[None, :, 0], y - other[None, :, 1]).min(axis=1)
        if (d > r_safe).any():
            return True
    return False


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", help="ring:N:SEED, dense:SEED or scn:SCENARIO:SEED")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("kind")
    ap.add_argument("--policy", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--window", type=float, default=120.0, help="s of history per loss")
    ap.add_argument("--oracle", action="store_true", help="pairwise avoidability per loss")
    args = ap.parse_args(argv)
    sc, seeds = scenario(args.case, args.kind, args.policy, args.overrides)
    w = World(sc, seed=seeds[0])
    rec = Recorder(w, int(round(args.window / sc.dt)))
    pending = []  # (loss no., a, b, t_loss, decisions (list of dict))
    closest = {}  # (a, b) -> true minimum distance since the pair was first watched
    n_loss = 0
    path = [w.positions.copy()]  # true positions after each step, m
    headings = [w.headings.copy()]
    detected = {}  # loss no. -> (step index in path of the first detection, capped)
    ids = [a.id for a in sc.aircraft] if sc.aircraft else [str(i) for i in range(w.n)]
    for _ in range(int(round(sc.duration / sc.dt))):
        w.step()
        path.append(w.positions.copy())
        headings.append(w.headings.copy())
        for key in list(closest):
            a, b = key
            if not (w.active[a] and w.active[b]):
                continue  # an aircraft that left stays where it was
            closest[key] = min(closest[key], float(np.hypot(*(w.positions[a] - w.positions[b]))))
        began = w.airspace.began[LOS]
        for a, b in began.tolist():
            n_loss += 1
            t_loss = w.time
            print(f"\n#{n_loss} t={t_loss:.0f} s  A={ids[a]} B={ids[b]}")
            for x, name in ((a, "A"), (b, "B")):
                print(f"  {name} timeline: {timeline(rec, x, t_loss)}")
            for x, y, name in ((a, b, "A"), (b, a, "B")):
                print(f"  {name} advice: {advice_runs(rec, x, y, t_loss)}")
            print("  every 10 s: t, distance, straight miss from truth / A's track / B's track, km")
            for i in range(len(rec.times) - 1, -1, -10)[::-1]:
                d = rec.straight_miss(i, a, b)
                print(
                    f"    {rec.times[i] - t_loss:+5.0f} s  {d[0] / 1e3:6.2f}  "
                    + " / ".join(f"{x / 1e3:6.2f}" for x in d[1:])
                    + f"  A {STATES[int(rec.states[i][a])]}, B {STATES[int(rec.states[i][b])]}"
                )
            for x, y, name in ((a, b, "A"), (b, a, "B")):
                for ts, st, tu, dec in zip(
                    rec.times, rec.states, rec.turns, rec.decisions, strict=True
                ):
                    if x not in dec or dec[x][0] == 0.0 or y not in dec[x][1]:
                        continue
                    f, pred = dec[x][0], dec[x][1][y]
                    print(
                        f"  {name} resumes at {ts - t_loss:+.0f} s, fraction {f:g}: "
                        f"predicted min distance to the other {pred[0]:.0f} m "
                        f"(holding {pred[1]:.0f} m, now {pred[3]:.0f} m), other's modes "
                        f"{pred[2]}, other {STATES[int(st[y])]} "
                        f"{np.degrees(tu[y]) / w.dt:+.1f} deg/s"
                    )
            r0 = w.policy.r_safe * (1.0 + w.policy.margin)
            first, capped = len(rec.times) - 1, True
            for i in range(len(rec.times) - 1, -1, -1):
                d = rec.straight_miss(i, a, b)
                if not min(d[2], d[3]) < r0:  # NaN (no track) is not a detection
                    capped = False
                    break
                first = i
            # rec.times[i] is the time at the start of step i's commands: path index
            t0 = rec.times[first]
            detected[n_loss] = (int(round(t0 / w.dt)), capped, t_loss)
            closest[(a, b)] = float(np.hypot(*(w.positions[a] - w.positions[b])))
            pending.append((n_loss, a, b))
        if w.done:
            break
    print("\ntrue minimum distance of each loss pair after it began (m):")
    print(", ".join(f"#{k} {closest[(a, b)]:.0f}" for k, a, b in pending))
    if args.oracle:
        print(
            "\navoidability (pairwise; turn limit, either side, tau 0-180 s, then straight):"
            "\n  loss  detection-to-loss s  A alone: actual/straight  B alone: actual/straight"
        )
        P, H = np.array(path), np.array(headings)
        for k, a, b in pending:
            i0, capped, t_loss = detected[k]
            i1 = min(int(round(t_loss / w.dt)) + int(round(60.0 / w.dt)), len(P) - 1)
            cells = []
            for x, y in ((a, b), (b, a)):
                for other in ("actual", "straight"):
                    if other == "actual":
                        py = P[i0 : i1 + 1, y]
                    else:
                        vy = w.speeds[y] * np.array([np.cos(H[i0, y]), np.sin(H[i0, y])])
                        py = P[i0, y] + np.arange(i1 - i0 + 1)[:, None] * w.dt * vy
                    ok = one_turn_avoids(
                        P[i0, x],
                        H[i0, x],
                        w.speeds[x],
                        w.max_turn_rate[x],
                        py,
                        w.dt,
                        sc.separation.r_safe,
                    )
                    cells.append("yes" if ok else "no")
            lead = t_loss - i0 * w.dt
            print(
                f"  #{k:<4d} {'>=' if capped else '  '}{lead:5.0f}"
                f"               {cells[0]:>3s}/{cells[1]:<3s}"
                f"                   {cells[2]:>3s}/{cells[3]:<3s}"
            )
    m = w.metrics()
    print({k: m[k] for k in ("los_pairs", "nmac_pairs", "extra_path_pct", "not_arrived")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
