"""``airspace-sim risk SCENARIO``: the risk ratio, NMACs with the resolver over NMACs without.

Examples::

    airspace-sim risk dense_random --seeds 0-15 --workers 2 --json out/risk.json
    airspace-sim risk ring --set traffic.count=64 --seeds 0-9

Every seed runs twice, with the scenario's resolver and with resolver ``"none"`` (same
traffic, noise and pilots; :mod:`airspace_sim.world.risk`). Prints one line per seed and the
ratios (``risk_ratio``, ``los_ratio``; undefined when the unequipped runs have none); with
``--json`` the same as one JSON object (undefined ratios as null). Details:
``docs/safety.md``.
"""

from __future__ import annotations

from airspace_sim.commands._args import add_set_option, check_output, positive_int

HELP = "risk ratio: NMACs (and LoS pairs) with the scenario's resolver over those without it"


def add_arguments(parser) -> None:
    parser.add_argument("scenario", help="scenario name or path to a .toml file")
    parser.add_argument("--seeds", default="0-9", help="seeds, e.g. 0-15, 5 or 0,3,7 (default 0-9)")
    add_set_option(parser, "in every run")
    parser.add_argument(
        "--workers", type=positive_int, default=1, help="local worker processes K (default 1)"
    )
    parser.add_argument("--json", metavar="PATH", help="also write the result as JSON to PATH")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _ratio_text(num: int, den: int, ratio: float) -> str:
    return f"{num}/{den} = {ratio:.4g}" if den else f"{num}/0 (undefined)"


def format_result(out: dict) -> str:
    """The result of :func:`~airspace_sim.world.risk.risk_ratio` as an aligned table (one
    row per seed, then the totals) and the two ratios."""
    from airspace_sim.world.risk import COUNTS

    head = ("seed", *COUNTS)
    rows = [[str(r[k]) for k in head] for r in out["per_seed"]]
    rows.append(["all", *(str(out[k]) for k in COUNTS)])
    widths = [max(len(h), *(len(r[j]) for r in rows)) for j, h in enumerate(head)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(head, widths))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows]
    lines.append("")
    lines.append(
        "risk ratio (NMAC pairs) "
        + _ratio_text(out["nmac_equipped"], out["nmac_unequipped"], out["risk_ratio"])
    )
    lines.append(
        "LoS ratio (LoS pairs)   "
        + _ratio_text(out["los_pairs_equipped"], out["los_pairs_unequipped"], out["los_ratio"])
    )
    return "\n".join(lines)


def run(args) -> int:
    import json

    from airspace_sim.commands.run import jsonable
    from airspace_sim.errors import UserError
    from airspace_sim.experiments.sweep import parse_seeds
    from airspace_sim.scenarios import load
    from airspace_sim.world.risk import risk_ratio

    # every option checked before any work
    seeds = parse_seeds(args.seeds)
    if args.json:
        check_output("--json", args.json)
    scenario = load(args.scenario, args.overrides)
    out = risk_ratio(scenario, seeds, progress=not args.no_progress, workers=args.workers)
    print(format_result(out))
    if args.json:
        try:
            with open(args.json, "w", encoding="utf-8") as f:
                json.dump({"scenario": scenario.name, **jsonable(out)}, f, indent=1)
                f.write("\n")
        except OSError as exc:
            raise UserError(f"--json {args.json}: cannot write: {exc.strerror}") from None
    return 0
