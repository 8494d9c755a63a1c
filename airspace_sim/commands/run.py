"""``airspace-sim run SCENARIO``: step a scenario's world, print its metrics, render frames.

Examples::

    airspace-sim run --list
    airspace-sim run head_on
    airspace-sim run ring --set traffic.count=64 --set traffic.radius=65000 --steps 300
    airspace-sim run demo --render out/demo --gif           # PNG frames + out/demo/run.gif
    airspace-sim run dense_random --json out/dense.json --seed 3
    airspace-sim run ring --checkpoint out/ring.pkl --steps 100   # run 100 steps, save
    airspace-sim run ring --resume out/ring.pkl --steps 100       # 100 more from there
    airspace-sim run ring --checkpoint out/ring.pkl --checkpoint-every 50   # survives a kill
    airspace-sim run --resume out/ring.pkl                        # the rest of the planned run

The scenario is a name from the repository's ``scenarios/`` folder or a path to a TOML
file. ``--set key=value`` changes any scenario key (dotted, e.g. ``sensor.sigma=30``,
``aircraft[0].speed=250``) before validation. The summary (scenario, seed, steps, metrics)
is printed as a table and written as ``summary.json`` into the render folder and/or to
``--json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from airspace_sim.commands._args import (
    add_set_option,
    check_output,
    fps,
    frame_size,
    positive_int,
    seed,
)
from airspace_sim.commands._signals import SigtermFlag, Terminated
from airspace_sim.errors import UserError, escape

HELP = "run a scenario: step the world, print metrics, optionally render frames"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario", nargs="?", help="scenario name (see --list) or path to a .toml file"
    )
    parser.add_argument("--list", action="store_true", help="list the shipped scenarios and exit")
    parser.add_argument(
        "--steps",
        type=positive_int,
        help="world steps to run (default: the scenario's duration / dt)",
    )
    parser.add_argument("--seed", type=seed, help="random seed (default: the scenario's seed)")
    add_set_option(parser)
    parser.add_argument(
        "--render",
        metavar="DIR",
        help="write a PNG per step (frame_00000.png, ...) and summary.json into DIR",
    )
    video = parser.add_mutually_exclusive_group()
    video.add_argument("--gif", action="store_true", help="also write DIR/run.gif (needs --render)")
    video.add_argument(
        "--mp4",
        action="store_true",
        help="also write DIR/run.mp4 (needs --render and imageio-ffmpeg)",
    )
    parser.add_argument(
        "--every",
        type=positive_int,
        default=1,
        metavar="N",
        help="render every N-th step (default 1)",
    )
    parser.add_argument(
        "--size",
        type=frame_size,
        default=(800, 800),
        metavar="WxH",
        help="frame size in pixels (default 800x800)",
    )
    parser.add_argument(
        "--fps",
        type=fps,
        default=10.0,
        help="frames per second of the GIF/MP4 (default 10)",
    )
    parser.add_argument(
        "--owners",
        metavar="IDS",
        help="whose tracks to draw: comma-separated aircraft ids, or 'all' "
        "(default: the RL agents, else the first aircraft that tracks)",
    )
    parser.add_argument("--json", metavar="PATH", help="write the summary as JSON to PATH")
    parser.add_argument(
        "--checkpoint",
        metavar="PATH",
        help="save the world to PATH at the end (and on Ctrl-C or SIGTERM) to resume later",
    )
    parser.add_argument(
        "--checkpoint-every",
        type=positive_int,
        metavar="N",
        help="also save the checkpoint every N steps (survives a killed run)",
    )
    parser.add_argument(
        "--resume",
        metavar="PATH",
        help="continue a run saved with --checkpoint (the scenario argument is optional)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no table")


# --------------------------------------------------------------------------- helpers


def jsonable(obj):
    """Metrics → plain JSON values (numpy scalars and arrays, non-finite floats → null)."""
    try:
        import numpy as np
    except ImportError:  # pragma: no cover
        np = None
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if np is not None and isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if np is not None and isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    return str(obj)


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    rows = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            rows.extend(_flatten(v, key + "."))
        else:
            rows.append((key, v))
    return rows


def _fmt(v) -> str:
    if isinstance(v, bool) or v is None:
        return str(v).lower() if isinstance(v, bool) else "-"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        if abs(v) >= 1e4:
            return f"{v:.0f}"
        return f"{v:.4g}"
    if isinstance(v, list):
        text = ", ".join(_fmt(x) for x in v[:8]) + (", ..." if len(v) > 8 else "")
        return f"[{text}]"
    return str(v)


def format_table(summary: dict) -> str:
    """The summary as an aligned two-column table (metrics flattened with dotted keys)."""
    head = [
        ("scenario", summary["scenario"]),
        ("seed", summary["seed"]),
        ("steps", summary["steps"]),
        ("simulated time (s)", summary["simulated_time"]),
        ("wall time (s)", summary["wall_time"]),
        ("steps per second", summary["steps_per_second"]),
    ]
    rows = [(k, escape(_fmt(v))) for k, v in head]  # the name comes from the file
    metrics = _flatten(summary.get("metrics") or {})
    width = max(len(k) for k, _ in rows + [(m, 0) for m, _ in metrics] + [("metric", 0)])
    lines = [f"{k:<{width}}  {v}" for k, v in rows]
    if metrics:
        lines += ["", f"{'metric':<{width}}  value", f"{'-' * width}  {'-' * 12}"]
        lines += [f"{k:<{width}}  {_fmt(v)}" for k, v in metrics]
    return "\n".join(lines)


def _write_json(path: Path, summary: dict) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(summary, indent=2) + "\n")
    except OSError as exc:
        raise UserError(f"cannot write {path}: {_why(exc)}") from None


def track_owners(snap, text: str | None):
    """The renderer's ``owners`` for the run's first :class:`Snapshot` ``snap``: ``--owners``
    ids or "all"; by default the RL agents, else the first aircraft that tracks (avoids),
    else aircraft 0."""
    if text:
        if text.strip() == "all":
            return "all"
        ids = [t.strip() for t in text.split(",") if t.strip()]
        unknown = [i for i in ids if i not in snap.ids]
        if unknown or not ids:
            known = ", ".join(snap.ids[:12]) + (", ..." if len(snap.ids) > 12 else "")
            bad = unknown[0] if unknown else text
            raise UserError(f"--owners: no aircraft {bad!r} (ids: {known})")
        return ids
    import numpy as np

    controlled = np.flatnonzero(snap.controlled)
    if controlled.size:
        return None  # the renderer's own default: the RL agents
    tracking = np.flatnonzero(snap.avoid)
    return [snap.ids[int(tracking[0])]] if tracking.size else None


class Frames:
    """The ``--render`` output: each added snapshot drawn by one :class:`Renderer` and written
    by one :class:`~airspace_sim.rendering.FrameWriter` (PNGs, optional GIF/MP4)."""

    def __init__(self, directory: Path, size, video: str | None, fps: float, owners=None):
        from airspace_sim.rendering import FrameWriter, Renderer

        try:
            self.writer = FrameWriter(directory, video=video, fps=fps)
        except UserError as exc:
            raise UserError(f"--render {directory}: {exc}") from None
        self.renderer = Renderer(*size, owners=owners)
        self.directory = self.writer.directory
        self.paths = self.writer.paths

    def add(self, snapshot) -> None:
        """Draw and write one :class:`~airspace_sim.world.snapshot.Snapshot`."""
        frame = self.renderer.render(snapshot)
        try:
            self.writer.add(frame)
        except OSError as exc:
            raise UserError(
                f"--render {self.directory}: cannot write a frame: {_why(exc)}"
            ) from None

    def close(self) -> Path | None:
        """Finish the video; its path, or None."""
        try:
            return self.writer.close()
        except OSError as exc:
            raise UserError(
                f"--render {self.directory}: cannot write the video: {_why(exc)}"
            ) from None


def _why(exc: OSError) -> str:
    return f"[Errno {exc.errno}] {exc.strerror}" if exc.errno else str(exc)


# --------------------------------------------------------------------------- checkpoints
# The file format and its authentication live in :mod:`airspace_sim.world.checkpoint`; here
# the options' names are put in front of its one-line errors.


def save_checkpoint(path: Path, world, meta: dict) -> None:
    """:func:`airspace_sim.world.checkpoint.save`, its errors naming ``--checkpoint``."""
    from airspace_sim.world import checkpoint

    try:
        checkpoint.save(path, world, meta)
    except UserError as exc:
        raise UserError(f"--checkpoint {exc}") from None


def load_checkpoint(path: Path):
    """:func:`airspace_sim.world.checkpoint.load`, its errors naming ``--resume``."""
    from airspace_sim.world import checkpoint

    try:
        return checkpoint.load(path)
    except UserError as exc:
        raise UserError(f"--resume {exc}") from None


# --------------------------------------------------------------------------- command


def run(args) -> int:
    from airspace_sim import scenarios

    if args.list:
        for name in scenarios.available():
            try:
                description = scenarios.load(name).description
            except UserError as exc:  # list the others anyway
                description = f"(invalid: {exc})"
            print(f"{name:<18} {escape(description)}")
        return 0
    _check_options(args)

    if args.resume:
        if args.overrides or args.seed is not None:
            raise UserError("--resume continues a saved run: --set and --seed cannot change it")
        world, meta = load_checkpoint(Path(args.resume))
        if args.scenario and args.scenario not in (meta["scenario"], meta.get("source")):
            raise UserError(
                f"--resume {args.resume}: it holds scenario {meta['scenario']!r}, "
                f"not {args.scenario!r}"
            )
        name, source, seed, overrides = (
            meta["scenario"],
            meta["source"],
            meta["seed"],
            meta["overrides"],
        )
        remaining = max(0, meta["total_steps"] - world.step_count)
        if not args.steps and not remaining:
            raise UserError(
                f"--resume {args.resume}: that run is complete; give --steps N to run further"
            )
        steps = args.steps or remaining
    else:
        if not args.scenario:
            raise UserError(
                "missing SCENARIO (a name from `airspace-sim run --list` or a .toml path)"
            )
        sc = scenarios.load(args.scenario, args.overrides)
        seed = sc.seed if args.seed is None else args.seed
        steps = args.steps or sc.n_steps
        name, source, overrides = sc.name, sc.source, list(args.overrides)
        from airspace_sim.world import World

        world = World(sc, seed=seed)

    frames = None
    if args.render:
        first = world.snapshot()
        frames = Frames(
            Path(args.render),
            args.size,
            "gif" if args.gif else "mp4" if args.mp4 else None,
            args.fps,
            track_owners(first, args.owners),
        )
        frames.add(first)

    planned_total = world.step_count + steps

    def checkpoint_meta() -> dict:
        return {
            "scenario": name,
            "source": source,
            "seed": seed,
            "overrides": overrides,
            "total_steps": planned_total,
        }

    def periodic_checkpoint(k: int) -> None:
        if args.checkpoint_every and (k + 1) % args.checkpoint_every == 0 and k + 1 < steps:
            save_checkpoint(Path(args.checkpoint), world, checkpoint_meta())

    start_step = world.step_count
    interrupted: KeyboardInterrupt | None = None
    failed: UserError | None = None  # a frame that could not be written: save, then report
    t0 = time.perf_counter()
    with SigtermFlag() as sigterm:
        try:
            interrupted = step_world(
                world, steps, name, args.quiet, frames, args.every, sigterm, periodic_checkpoint
            )
        except UserError as exc:
            if not args.checkpoint or frames is None or not str(exc).startswith("--render"):
                raise
            failed = exc
        wall = time.perf_counter() - t0
        stopped = interrupted or failed
        # a SIGTERM while the outputs are written waits for them, then ends the run
        status = _finish(
            args,
            world,
            frames,
            name,
            source,
            seed,
            overrides,
            start_step,
            wall,
            checkpoint_meta(),
            stopped,
        )
        if sigterm.received and stopped is None:
            raise Terminated
        return status


def step_world(
    world,
    steps: int,
    desc: str,
    quiet: bool,
    frames=None,
    every: int = 1,
    sigterm=None,
    after_step=None,
) -> KeyboardInterrupt | None:
    """Step ``world`` up to ``steps`` times behind a tqdm bar (the ``run`` and ``replay``
    loop): a frame every ``every`` steps, at the last and when :attr:`World.everybody_left`
    (which stops early: nothing more to see); ``after_step(k)`` after step ``k`` (0-based).
    Returns the Ctrl-C or SIGTERM (:class:`Terminated`, when ``sigterm`` is a
    :class:`SigtermFlag`) that stopped it, else None; anything else propagates."""
    from tqdm import tqdm

    bar = tqdm(
        total=steps,
        unit="step",
        desc=desc,
        disable=quiet or not sys.stderr.isatty(),
        file=sys.stderr,
        leave=False,
    )
    try:
        for k in range(steps):
            if sigterm is not None and sigterm.received:
                raise Terminated
            world.step()
            left = world.everybody_left
            if frames is not None and ((k + 1) % every == 0 or k + 1 == steps or left):
                frames.add(world.snapshot())
            bar.update(1)
            if after_step is not None:
                after_step(k)
            if left:
                break
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (Terminated)
        return exc
    finally:
        bar.close()
    return None


def write_summary(args, summary: dict, frames, video) -> None:
    """Write ``summary`` to ``<--render>/summary.json`` (with the frame count and video)
    and to ``--json``, whichever were asked for."""
    if frames is not None:
        summary["frames"] = len(frames.paths)
        if video is not None:
            summary["video"] = str(video)
        _write_json(frames.directory / "summary.json", summary)
    if args.json:
        _write_json(Path(args.json), summary)


def _finish(
    args, world, frames, name, source, seed, overrides, start_step, wall, meta, stopped
) -> int:
    """Summarise, write the outputs and save the checkpoint of a run that ended (finished,
    interrupted or ``stopped`` by a failed frame write); re-raise what stopped it."""
    done = world.step_count - start_step
    if args.checkpoint:  # first: the outputs below may fail on the same full disk
        if stopped is None:  # finished (or everybody left): resuming needs --steps
            meta = {**meta, "total_steps": world.step_count}
        save_checkpoint(Path(args.checkpoint), world, meta)
    if isinstance(stopped, UserError):
        raise UserError(f"{stopped}; checkpoint (step {world.step_count}) in {args.checkpoint}")
    video = frames.close() if frames is not None else None
    summary = {
        "scenario": name,
        "source": source,
        "seed": seed,
        "overrides": overrides,
        "steps": done,
        "total_steps": world.step_count,
        "dt": float(world.dt),
        "simulated_time": float(world.time),
        "wall_time": round(wall, 3),
        "steps_per_second": round(done / wall, 1) if wall > 0 else None,
        "interrupted": stopped is not None,
        "all_left": bool(world.everybody_left),
        "metrics": jsonable(world.metrics()),
    }
    if args.checkpoint:
        summary["checkpoint"] = str(args.checkpoint)
    write_summary(args, summary, frames, video)
    if not args.quiet:
        print(format_table(summary))
        if frames is not None:
            print(
                f"\n{len(frames.paths)} frames in {frames.directory}"
                + (f", {video}" if video else "")
            )
        if args.checkpoint:
            print(f"checkpoint (step {world.step_count}) in {args.checkpoint}")
    if stopped is not None:
        raise stopped
    return 0


def _check_options(args) -> None:
    """Option combinations and every output location, checked before any work."""
    from airspace_sim.world import checkpoint

    if (args.gif or args.mp4) and not args.render:
        raise UserError(
            f"--{'gif' if args.gif else 'mp4'} needs --render DIR (the frames go there)"
        )
    if args.checkpoint_every and not args.checkpoint:
        raise UserError("--checkpoint-every needs --checkpoint PATH")
    if args.checkpoint:
        target = Path(args.checkpoint)
        if target.is_dir() or (target.exists() and not checkpoint.is_checkpoint(target)):
            raise UserError(
                f"--checkpoint {target}: exists and is not an airspace-sim checkpoint; "
                "not overwriting it"
            )
        check_output("--checkpoint", target)
        try:
            checkpoint.load_key(create=True)  # now, not when the first save is due
        except UserError as exc:
            raise UserError(f"--checkpoint {target}: {exc}") from None
    if args.json:
        check_output("--json", args.json)
    if args.render:
        check_output("--render", args.render, folder=True)
