"""What a configuration costs besides the motion, for ``gonio plan``'s time estimate.

A run's wall time is the motion (the servos' trapezoidal profiles, which ``gonio plan`` predicts
from the rig file; a simulated rig runs them ``time_scale`` times faster), plus per move the bus
traffic and settling after the profile ends, plus per configuration the capture and the
bookkeeping. The last two are not in the rig file. They come from a previous run of the same rig
(``gonio plan --timing-from RUN``: medians of ``RUN/log.jsonl``) or, without one, from the
figures measured here for the simulated cameras (:data:`MEASURED`). For a real camera without a
previous run only the exposure time is known, and the estimate says so.
"""

from __future__ import annotations

import json
import statistics
from dataclasses import dataclass
from pathlib import Path

from gonio.errors import FormatError


@dataclass(frozen=True)
class Costs:
    """Wall-clock seconds per configuration besides the motion profile.

    Attributes
    ----------
    capture_s : camera and processing per configuration, or None when unknown.
    move_overhead_s : per move, on top of the profile time: Sync Write, polling, settling.
    book_s : per configuration: journal and log.
    source : where the figures come from (printed with the estimate).
    """

    capture_s: float | None
    move_overhead_s: float
    book_s: float
    source: str


#: Costs in seconds (per configuration, per move beyond its profile, bookkeeping), medians of
#: RUN/log.jsonl of ``gonio acquire --rig sim --plan demo-quick`` (time scale 60) on a 2-core
#: machine shared with other jobs: the virtual camera renders, writes and merges about 3 DNG
#: frames per configuration, mostly waiting for the CPU, so an idle machine takes less.
#: ``sim-sample`` reads the truth directly, plus the rig file's capture_time_s.
#: ``benchmarks/bench_imaging.py`` and ``benchmarks/bench_rig.py`` measure the time split.
MEASURED = {
    "sim": Costs(
        2.99, 0.043, 0.0075, "measured: virtual camera, demo-quick on a busy 2-core machine"
    ),
    "sim-sample": Costs(0.001, 0.043, 0.002, "measured: direct sim-sample reading"),
}


def default_costs(rig) -> Costs:
    """The costs of :data:`MEASURED` for the rig's camera kind; unknown capture for real ones."""
    from gonio.rigs.factory import camera_kind

    kind = camera_kind(rig)
    extra = float(rig.camera.get("capture_time_s", 0.0))
    if kind in MEASURED:
        c = MEASURED[kind]
        return Costs(c.capture_s + extra, c.move_overhead_s, c.book_s, c.source)
    return Costs(
        None,
        MEASURED["sim"].move_overhead_s,
        MEASURED["sim"].book_s,
        f"capture cost of camera kind {kind!r} unknown: measure it with --timing-from RUN",
    )


def costs_from_run(run_dir: str | Path) -> Costs:
    """Medians of the configurations recorded in ``RUN/log.jsonl`` (FormatError if none)."""
    path = Path(run_dir) / "log.jsonl"
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise FormatError(f"--timing-from {run_dir}: cannot read {path.name} ({exc})") from None
    samples = []
    for line in lines:
        try:
            e = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut by a kill
        if e.get("event") == "sample":
            samples.append(e)
    if not samples:
        raise FormatError(f"--timing-from {run_dir}: the log records no configuration")

    def num(s: dict, key: str) -> float:  # a non-finite figure is logged as null
        v = s.get(key)
        return 0.0 if v is None else float(v)

    def med(key: str) -> float:
        return float(statistics.median(num(s, key) for s in samples))

    overhead = statistics.median(num(s, "move_wall_s") - num(s, "profile_wall_s") for s in samples)
    return Costs(
        med("t_capture"),
        max(0.0, float(overhead)),
        med("t_book"),
        f"measured: medians of {len(samples)} configurations of {run_dir}",
    )
