"""The run engine: plan -> (move, settle, capture, record) for every configuration, resumable.

``acquire(...)`` executes a plan on a rig and keeps the books in ``RUN/``:

* ``journal.sqlite`` — the journal (:mod:`gonio.acquire.journal`); resuming continues from it
  with no lost and no duplicated sample;
* ``log.jsonl`` — a structured log, one JSON object per line (events, per-configuration timings,
  servo faults);
* ``sim_goals.jsonl`` — for the simulated rig, every Goal Position the emulated servos received
  (and ``sim_packets.jsonl``, every instruction packet, with ``[sim] packet_log = true``);
* ``table.brdf.h5`` — the samples as a table through :mod:`gonio.io` when the run completes.

The devices (light, camera, servos) come open from the rig session
(:func:`gonio.rigs.session.open_rig`), which closes them in reverse once the engine has parked
the rig; the engine measures through the camera and the light
(:func:`gonio.acquire.imaging.measurement`: brackets -> HDR -> pose -> radiometry for a RAW
camera). The run directory appears with its complete journal (:mod:`gonio.acquire.rundir`).
Each stage of the plan is planned once (inverse kinematics, refusals with reasons, travel-time
ordering: :mod:`gonio.acquire.planning`) and journaled atomically before any motion; later
stages see earlier stages' samples. A dynamic plan (``optimal``, ``guided``) decides each batch
from the journaled samples with their sigma and journals the decision with it
(:mod:`gonio.acquire.decide`); it ends when a decision says stop. Once the servos
are powered every way out parks the rig, or turns torque off when it cannot
(:mod:`gonio.acquire.stopping`). SIGINT/SIGTERM (:mod:`gonio.interrupts`): the first finishes the
configuration in progress, parks and stops; a second abandons the configuration and parks.
A configuration whose frame cannot be measured (:class:`gonio.errors.FrameError`, after the
camera's one retake) is journaled as ``rejected`` with the reason and skipped; it counts as
finished for completeness and is not retried on resume.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gonio import interrupts
from gonio.acquire import rundir, stopping
from gonio.acquire.decide import (
    NextStage,
    batches,
    next_stage,
    results_of,
    spent_of,
    write_chosen_plan,
)
from gonio.acquire.journal import Journal, PlannedConfig
from gonio.acquire.planning import StagePlan as StagePlan  # re-exported: planning moved out
from gonio.acquire.planning import dry_run as dry_run
from gonio.acquire.planning import plan_stage as plan_stage
from gonio.acquire.planning import refuse_if_any, refuse_if_nothing, start_pose
from gonio.acquire.plans import Plan, Spent, load_plan
from gonio.acquire.runlog import RunLog
from gonio.errors import DeviceError, FrameError, PlanError
from gonio.rigs.config import RigConfig, load_rig
from gonio.rigs.devices import Geometry
from gonio.rigs.kinematics import Kinematics, Pose

# --- the run ------------------------------------------------------------------------------


@dataclass
class RunSummary:
    """What a run (or a resumed part of it) did."""

    run_dir: str
    planned: int
    refused: int
    done: int
    measured_now: int
    complete: bool
    table: str | None
    table_note: str
    bus: dict = field(default_factory=dict)
    wall_s: float = 0.0
    rejected: int = 0  # accepted configurations skipped because their frame could not be measured
    batches: list = field(default_factory=list)  # a dynamic plan's decisions (decide.batches)
    chosen_plan: str | None = None  # RUN/plan_chosen.toml of a complete dynamic run


def open_run(run_dir: Path) -> tuple[Journal, RigConfig, Plan]:
    """Open an existing run: its journal, and the rig and plan recorded in it."""
    return rundir.open_run(Path(run_dir))


def acquire(
    out: str | Path,
    rig: str | Path | RigConfig | None = None,
    plan: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    on_sample: Callable[[int, object], None] | None = None,
    write_table: bool = True,
    strict: bool = False,
    exposure_planning: bool | None = None,
    open_devices: Callable[[RigConfig, Path], AbstractContextManager] | None = None,
) -> RunSummary:
    """Run (or resume) an acquisition; see the module docstring.

    Parameters
    ----------
    out : run directory (created; must be empty unless ``resume``).
    rig, plan : rig name/path/config and plan name/path. When resuming the journal's copies
        are used so that a resumed run is the same run; a ``rig`` that differs from the
        recorded one is refused (PlanError) rather than ignored.
    progress : show a rich progress bar with ETA.
    strict : refuse the whole plan (PlanError, nothing moved, no run directory) if any of its
        poses is refused; later stages of an adaptive plan are checked before their motion.
    on_sample : called as ``on_sample(n, session)`` after each sample, with the number measured
        so far in this process and the open :class:`gonio.rigs.session.RigSession` (tests use
        it to inject faults into the emulator mid-run).
    exposure_planning : RAW cameras only: plan each configuration's exposures from the previous
        frame (default: the rig file's ``camera.planning``, true) or use fixed brackets.
    open_devices : ``open_devices(rig, run_dir)``, a context manager yielding the
        :class:`gonio.rigs.session.RigSession` with the rig's devices open (default:
        :func:`open_session`); the run measures through its camera and light
        (:func:`gonio.acquire.imaging.measurement`). The command line binds ``--sim-faults``
        and ``--time-scale`` here.

    Every way out once the servos are powered parks the rig when it can and switches torque off
    when it cannot (:mod:`gonio.acquire.stopping`); the outcome is added to the exception as a
    note, logged, and journaled. A start that fails before the rig is ready leaves no run
    directory behind.
    """
    run_dir = Path(out)
    try:
        return _acquire(
            run_dir, rig, plan, resume, progress, on_sample, write_table, strict,
            exposure_planning, open_devices,
        )  # fmt: skip
    except Exception as exc:  # a storage failure anywhere: one StorageError saying what is kept
        err = rundir.storage_failure(exc, run_dir)
        if err is None:
            raise
        raise err from None


def _acquire(
    run_dir: Path, rig, plan, resume, progress, on_sample, write_table, strict,
    exposure_planning, open_devices,
) -> RunSummary:  # fmt: skip
    # signals are recorded, not raised, except in the loop over configurations (see
    # gonio.interrupts): the flag is checked wherever stopping is safe
    with interrupts.installed() as flag, flag.shielded(), rundir.RunHold(run_dir) as hold:
        if flag.requested:  # a signal during start-up whose exception was swallowed
            raise flag.interrupted()
        first = None  # stage 0 of a new run, planned before anything is created
        if resume:
            hold.take()  # before anything is read: InUseError while another process writes it
            journal, rig_cfg, plan_obj = open_run(run_dir)
            if rig is not None:
                _same_rig_or_refuse(journal, rig_cfg, rig, run_dir)
            created, existed = False, True
        else:
            if rig is None or plan is None:
                raise PlanError("a new run needs --rig and --plan")
            rig_cfg = rig if isinstance(rig, RigConfig) else load_rig(rig)
            plan_obj, spec = load_plan(plan)
            # the first stage is planned before anything is created or the bus opened: a plan
            # with nothing the rig can reach (or, strict, with any pose it cannot) moves nothing
            first = next_stage(rig_cfg, plan_obj, 0, [], Spent(), start_pose(rig_cfg), 0)
            if strict:
                refuse_if_any(first.plan)
            refuse_if_nothing(first.plan)
            meta = {"strict": "1" if strict else "0"}
            if exposure_planning is not None:  # a resumed run keeps the choice
                meta["exposure_planning"] = "1" if exposure_planning else "0"
            existed = rundir.start_new(run_dir, rig_cfg, spec, meta, hold)
            journal = Journal(run_dir)
            created = True
        if exposure_planning is None and journal.get_meta("exposure_planning") is not None:
            exposure_planning = journal.get_meta("exposure_planning") == "1"
        run = _Run(run_dir, journal, rig_cfg, plan_obj, flag, resume, progress, on_sample, first)
        run.hold = hold
        if hold.lock is not None and hold.lock.stale_pid is not None:  # its holder was killed
            run.log("lock_taken_over", stale_pid=hold.lock.stale_pid)
        try:
            run.execute(open_devices, exposure_planning)
        except BaseException as exc:
            if not run.started:  # a latched servo error found at open: journaled when resuming
                stopping.record_fault(
                    journal, run.log, exc, "; ".join(getattr(exc, "__notes__", ()))
                )
            run.close()
            if created and not run.started:
                rundir.discard(run_dir, existed)
            raise
        return run.finish(write_table)


def _same_rig_or_refuse(journal: Journal, recorded: RigConfig, rig, run_dir: Path) -> None:
    given = rig if isinstance(rig, RigConfig) else load_rig(rig)
    if given.text != recorded.text:
        journal.close()
        raise PlanError(
            f"{run_dir} was recorded on rig {recorded.name!r} ({recorded.source}); --resume"
            f" continues it on that rig, not on {given.name!r} ({given.source}): drop --rig"
        )


def open_session(rig: RigConfig, run_dir: Path, **options):
    """The rig session of a run: :func:`gonio.rigs.session.open_rig` with the run directory for
    the simulator's logs, raising a stop asked for while the camera opened before any servo is
    powered. ``options`` go to ``open_rig`` (``faults``, ``time_scale``)."""
    from gonio.rigs.session import open_rig

    return open_rig(rig, log_dir=run_dir, before_servos=_stop_if_asked, **options)


def _stop_if_asked() -> None:
    if interrupts.FLAG.requested:
        raise interrupts.FLAG.interrupted()


class _Run:
    """One execution of :func:`acquire` (state shared by its phases)."""

    def __init__(
        self, run_dir, journal, rig, plan, flag, resume, progress, on_sample, first_stage=None
    ) -> None:
        self.run_dir = run_dir
        self.journal = journal
        self.rig = rig
        self.plan = plan
        self.flag = flag
        self.progress = progress
        self.on_sample = on_sample
        self.t_start = time.monotonic()
        self.log = RunLog(run_dir / "log.jsonl")
        self.log("resume" if resume else "start", rig=rig.name, plan=plan.name, pid=os.getpid())
        self.started = False  # servos powered: from here on the run persists
        self.measured_now = 0
        self.bus: dict = {}
        self.stop_note = ""
        self._closed = False
        self.first_stage: NextStage | None = first_stage  # stage 0 planned before the bus opened
        self.channels: tuple[str, ...] = ()  # the camera's, once the devices are open
        self.hold = rundir.RunHold(run_dir)  # the run folder's lock, held by acquire()

    def execute(self, open_devices, exposure_planning) -> None:
        from gonio.acquire.imaging import measurement

        flag = self.flag
        # the session opens the light and the camera before the servos, and closes all of them
        # in reverse on the way out; the rig is parked below, before that
        with (open_devices or open_session)(self.rig, self.run_dir) as ses:
            chain = ses.chain
            self.started = True
            try:
                with flag.deferred():
                    chain.should_abort = lambda: flag.count >= 2
                    if flag.requested:
                        raise flag.interrupted()
                    camera = measurement(ses, self.run_dir, exposure_planning)
                    self.channels = tuple(camera.channels)
                    self._loop(chain, camera, ses)
                    chain.should_abort = lambda: False
            except BaseException as exc:
                # from here on signals are recorded, not raised: nothing may skip the park
                with flag.shielded():
                    chain.should_abort = lambda: False
                    self._stopped_by(exc, chain)
                raise
            with flag.shielded():
                reason = "interrupted" if flag.requested else "complete"
                if flag.requested:
                    self.log("interrupted", signal=flag.signum)
                parked, phrase = stopping.bring_to_rest(chain, flag)
                stopping.record_stop(self.journal, self.log, reason, parked, phrase)
                self.bus = chain.bus_stats()
                self.stop_note = phrase
            if not parked:
                raise DeviceError(f"run ended but the rig could not be parked: {phrase}")
            self.log("parked", pose=self.rig.park_deg)

    def _stopped_by(self, exc: BaseException, chain) -> None:
        """Bring the rig to rest after ``exc``; log, journal and note the outcome on ``exc``."""
        if isinstance(exc, DeviceError):
            self.log("device_error", message=str(exc))
        elif isinstance(exc, KeyboardInterrupt):
            self.log("interrupted", signal=self.flag.signum, message=str(exc))
        else:
            self.log("aborted", error=type(exc).__name__, message=str(exc))
        parked, phrase = stopping.bring_to_rest(chain, self.flag, exc)
        stopping.record_fault(self.journal, self.log, exc, phrase)
        stopping.record_stop(self.journal, self.log, _reason(exc), parked, phrase)
        if parked:
            self.log("parked", pose=self.rig.park_deg)
        try:
            self.bus = chain.bus_stats()
        except Exception:
            pass
        exc.add_note(phrase)
        if getattr(exc, "next_step", None):  # a servo fault: what the policy table says to do
            exc.add_note(f"next: {exc.next_step}")

    def _loop(self, chain, camera, ses) -> None:
        rig, plan, journal, log, flag = self.rig, self.plan, self.journal, self.log, self.flag
        kin = Kinematics(rig)
        scale = float(ses.time_scale)  # rig seconds per wall second
        with _Progress(self.progress) as bar:
            start_deg = start_pose(rig)
            stage = -1
            while plan.dynamic or stage + 1 < plan.n_stages:
                stage += 1
                if not journal.stage_planned(stage):
                    if stage == 0 and self.first_stage is not None:
                        nxt = self.first_stage  # no samples yet: the same plan, not made twice
                    else:
                        t0 = time.monotonic()
                        nxt = next_stage(
                            rig, plan, stage, results_of(journal), spent_of(journal),
                            start_deg, journal.next_index(),
                        )  # fmt: skip
                        if nxt.decision is not None:
                            log("decision_wall_s", stage=stage, s=time.monotonic() - t0)
                    sp = nxt.plan
                    if journal.get_meta("strict") == "1":
                        refuse_if_any(sp)
                    journal.plan_stage(stage, sp.configs, nxt.decision)
                    if nxt.decision is not None:
                        log("decision", **nxt.decision)
                    log(
                        "stage_planned",
                        stage=stage,
                        accepted=len(sp.accepted),
                        refused=len(sp.refused),
                        predicted_motion_s=float(np.sum(sp.move_s)),
                    )
                    for c in sp.refused:
                        log("refused", idx=c.idx, reason=c.reason)
                if plan.dynamic and journal.decisions().get(stage, {}).get("stop") is not None:
                    break
                stage_cfgs = [
                    c for c in journal.configs(stage) if c.status in ("planned", "rejected")
                ]
                if stage_cfgs:
                    # the next stage starts where this one ends (deterministic on resume)
                    start_deg = dict(stage_cfgs[-1].joints_deg)
                counts = journal.counts()
                bar.set(counts["planned"], counts["done"] + counts["rejected"])
                for cfg in journal.pending(stage):
                    # the flag, not the exception: a library callback may swallow the latter
                    if flag.count >= 2:
                        raise flag.interrupted()
                    if flag.requested:
                        return
                    self.check_storage()
                    if _measure(chain, camera, kin, journal, log, cfg, scale):
                        self.measured_now += 1
                    bar.advance()
                    if self.on_sample is not None:
                        self.on_sample(self.measured_now, ses)
                if flag.requested:
                    return
        self.check_storage()

    def check_storage(self) -> None:
        """StorageError if the run folder is gone or the log could not be written (the
        journal's own failures raise where they happen)."""
        self.hold.check()
        self.log.check()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.log.close()
            self.journal.close()

    def finish(self, write_table: bool) -> RunSummary:
        journal, flag = self.journal, self.flag
        counts = journal.counts()
        complete = (
            not flag.requested
            and stages_complete(journal, self.plan)
            and counts["done"] + counts["rejected"] == counts["planned"]
        )
        table, note, chosen, rows = None, "", None, []
        try:
            if complete and write_table:
                table, note = write_run_table(journal, self.rig, self.channels)
                if counts["rejected"]:
                    note += f"; {rejected_note(journal)}"
                self.log("table", path=table, note=note)
            if complete and self.plan.dynamic:
                chosen = str(write_chosen_plan(journal, self.run_dir, self.plan))
                self.log("chosen_plan", path=chosen)
            rows = batches(journal) if self.plan.dynamic else []
            if rows and complete:  # the simulator knows its truth: how the run went, truly
                true = self.plan.true_errors(results_of(journal), journal.decisions(), self.rig)
                for r in rows:
                    r["true_error"] = true.get(r["stage"])
            self.log(
                "end", complete=complete, **counts, measured_now=self.measured_now, bus=self.bus
            )
        except KeyboardInterrupt as exc:  # while writing the table: the rig is at rest already
            exc.add_note(self.stop_note)
            raise
        finally:
            self.close()
        if flag.requested:
            exc = flag.interrupted()
            exc.add_note(self.stop_note)
            raise exc
        return RunSummary(
            str(self.run_dir),
            counts["planned"],
            counts["refused"],
            counts["done"],
            self.measured_now,
            complete,
            table,
            note,
            self.bus,
            time.monotonic() - self.t_start,
            counts["rejected"],
            rows,
            chosen,
        )


def stages_complete(journal: Journal, plan: Plan) -> bool:
    """Every stage planned: all ``n_stages`` of a fixed plan, a stop decision of a dynamic one."""
    if plan.dynamic:
        return any(d.get("stop") is not None for d in journal.decisions().values())
    return all(journal.stage_planned(s) for s in range(plan.n_stages))


def _reason(exc: BaseException) -> str:
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, DeviceError):
        return "device error"
    return f"error ({type(exc).__name__})"


def rejected_note(journal: Journal) -> str:
    """One line on the configurations a run skipped (FrameError), with the first reason."""
    rej = [c for c in journal.configs() if c.status == "rejected"]
    if not rej:
        return "no configuration rejected"
    return (
        f"{len(rej)} configuration(s) rejected, their frame could not be measured"
        f" (#{rej[0].idx}: {rej[0].reason})"
    )


def _measure(
    chain, camera, kin: Kinematics, journal: Journal, log: RunLog, cfg: PlannedConfig, scale=1.0
) -> bool:
    """Move, capture and journal one configuration; False when its frame could not be
    measured (:class:`gonio.errors.FrameError`): it is journaled as rejected and skipped."""
    t0 = time.monotonic()
    res = chain.move(cfg.joints_deg)
    t1 = time.monotonic()
    pose = kin.joints_deg_to_pose(res.reached_deg)
    wi, wo = kin.forward(pose)
    lay = kin.rig.layout
    geom = Geometry(
        cfg.idx,
        dict(res.reached_deg),
        wi,
        wo,
        light_pos_m=wi * lay.light_distance_m,
        camera_pos_m=wo * lay.camera_distance_m,
    )
    try:
        cap = camera.capture(geom)
    except FrameError as exc:
        # the devices work but this frame cannot be measured: skip it, as an operator would
        journal.reject(cfg.idx, str(exc))
        log("rejected", idx=cfg.idx, stage=cfg.stage, seq=cfg.seq, reason=str(exc))
        return False
    t2 = time.monotonic()
    # imaging cameras measure the directions from the holder pose and the light position
    wi = np.asarray(cap.meta.get("wi", wi), dtype=float)
    wo = np.asarray(cap.meta.get("wo", wo), dtype=float)
    keys = ("t_exposure", "t_camera", "t_processing", "t_camera_cpu", "t_processing_cpu")
    extra = {k: cap.meta[k] for k in keys if k in cap.meta}
    timings = {"motion": res.motion_s, "settle": res.settle_s, "capture": t2 - t1}
    tb = time.monotonic()
    timings["book"] = tb - t2
    journal.record(cfg.idx, res.reached_deg, wi, wo, cap.value, cap.sigma, timings, res.recoveries)
    timings["book"] = time.monotonic() - t2
    log(
        "sample",
        idx=cfg.idx,
        stage=cfg.stage,
        seq=cfg.seq,
        recoveries=res.recoveries,
        polls=res.polls,
        move_wall_s=t1 - t0,
        profile_wall_s=res.predicted_s / scale,  # what `gonio plan` predicts for this move
        **{f"t_{k}": v for k, v in timings.items()},
        **extra,
    )
    return True


def write_run_table(journal: Journal, rig: RigConfig, channels) -> tuple[str | None, str]:
    """Write ``RUN/table.brdf.h5`` through gonio.io; returns (path or None, note).

    The scattered samples sit at the root, the gridded half/diff table resampled from them in
    ``/gridded``; reciprocal pairs of the plan are compared (see :mod:`gonio.acquire.table`).
    """
    from gonio.acquire.table import write_run_tables

    path, note, _ = write_run_tables(journal, rig, channels)
    return path, note


class _Progress:
    """rich progress bar with ETA (no-op when disabled or not on a terminal)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self._p = None
        self._task = None

    def __enter__(self):
        if self.enabled:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._p = Progress(
                TextColumn("acquire"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                transient=False,
            )
            self._p.__enter__()
            self._task = self._p.add_task("acquire", total=None)
        return self

    def __exit__(self, *exc):
        if self._p is not None:
            self._p.__exit__(*exc)

    def set(self, total: int, done: int) -> None:
        if self._p is not None:
            self._p.update(self._task, total=total, completed=done)

    def advance(self) -> None:
        if self._p is not None:
            self._p.advance(self._task)


def pose_deg_of(kin: Kinematics, pose: Pose) -> dict[str, float]:
    return kin.pose_to_joints_deg(pose)


def to_deg(x: float) -> float:
    return math.degrees(x)
