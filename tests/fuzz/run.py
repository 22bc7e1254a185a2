"""Run fuzz cases through the worker pool, summarize them, and replay one case.

``python -m tests.fuzz.run --cases 2000 --seed 23`` runs a campaign and prints the counts per
kind; ``python -m tests.fuzz.run --replay 23:417`` rebuilds case 417 of seed 23, writes the
mutated file to ``--out`` (default: the current folder) and runs its check in this process,
printing the verdict and, for an escaped exception, the full traceback.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import traceback
from dataclasses import dataclass
from pathlib import Path

from tests.fuzz.corpus import Seed, build_corpus
from tests.fuzz.mutate import Case, make_case
from tests.fuzz.pool import Verdict, Worker

PASSING = ("error", "load")


@dataclass
class Result:
    case: Case
    verdict: Verdict

    @property
    def ok(self) -> bool:
        return self.verdict.outcome in PASSING

    def report(self) -> str:
        return (
            f"{self.verdict.outcome.upper()}: {self.verdict.detail}\n    {self.case.describe()}"
            f"\n    replay: python -m tests.fuzz.run --replay {self.case.case_id}"
        )


def _case_path(folder: Path, case: Case) -> Path:
    """Mutants keep their source's file name (the message must name it) in their own folder."""
    d = folder / f"case{case.index}"
    d.mkdir(parents=True, exist_ok=True)
    return d / case.seed.path.name


def run_cases(
    master: int, indices: range, seeds: list[Seed], folder: Path, keep_failures: Path | None = None
) -> list[Result]:
    """Judge cases ``indices`` of seed ``master`` in one worker; mutants are deleted after use."""
    warm = [(s.kind, str(s.path)) for s in {s.kind: s for s in seeds}.values()]
    worker = Worker(warm)
    results = []
    try:
        for i in indices:
            case = make_case(master, i, seeds)
            p = _case_path(folder, case)
            p.write_bytes(case.data)
            v = worker.run(case.seed.kind, str(p))
            r = Result(case, v)
            results.append(r)
            if not r.ok and keep_failures is not None:
                keep_failures.mkdir(parents=True, exist_ok=True)
                (keep_failures / f"{master}_{i}_{p.name}").write_bytes(case.data)
            p.unlink()
            p.parent.rmdir()
    finally:
        worker.close()
    return results


def summary(results: list[Result]) -> str:
    """Counts per kind: cases, typed errors, loads, failures (by outcome), as a table."""
    by: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for r in results:
        by[r.case.seed.kind][r.verdict.outcome] += 1
    lines = [f"{'kind':<11} {'cases':>6} {'errors':>7} {'loads':>6} {'fail':>5} {'hang':>5} "
             f"{'memory':>6} {'crash':>5}"]  # fmt: skip
    total: collections.Counter = collections.Counter()
    for kind in sorted(by):
        c = by[kind]
        total += c
        lines.append(
            f"{kind:<11} {sum(c.values()):>6} {c['error']:>7} {c['load']:>6} {c['fail']:>5} "
            f"{c['hang']:>5} {c['memory']:>6} {c['crash']:>5}"
        )
    lines.append(
        f"{'total':<11} {sum(total.values()):>6} {total['error']:>7} {total['load']:>6} "
        f"{total['fail']:>5} {total['hang']:>5} {total['memory']:>6} {total['crash']:>5}"
    )
    return "\n".join(lines)


def replay(case_id: str, out: Path, corpus_dir: Path) -> int:
    """Rebuild one case, write its file into ``out`` and run its check here, verbosely."""
    from tests.fuzz import worker

    master, index = (int(x) for x in case_id.split(":"))
    seeds = build_corpus(corpus_dir)
    case = make_case(master, index, seeds)
    out.mkdir(parents=True, exist_ok=True)
    p = out / case.seed.path.name
    p.write_bytes(case.data)
    print(case.describe())
    print(f"mutant written to {p}")
    from gonio.errors import GonioError

    try:
        print(worker.CHECKS[case.seed.kind](str(p)))
    except GonioError:
        pass  # a typed error: the verdict below shows it
    except Exception:
        traceback.print_exc()
    print(worker.judge(case.seed.kind, str(p)))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz.run", description=__doc__)
    ap.add_argument("--seed", type=int, default=23, help="master seed")
    ap.add_argument("--cases", type=int, default=200)
    ap.add_argument("--start", type=int, default=0, help="first case index")
    ap.add_argument("--replay", metavar="SEED:INDEX", help="replay one case in this process")
    ap.add_argument("--out", type=Path, default=Path("."), help="where --replay writes the file")
    ap.add_argument("--keep", type=Path, help="copy every failing mutant into this folder")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        if args.replay:
            return replay(args.replay, args.out, Path(tmp) / "corpus")
        seeds = build_corpus(Path(tmp) / "corpus")
        results = run_cases(
            args.seed, range(args.start, args.start + args.cases), seeds, Path(tmp), args.keep
        )
    for r in results:
        if not r.ok:
            print(r.report())
    print(summary(results))
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
