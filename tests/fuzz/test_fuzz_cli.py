"""The command line on a sample of mutated files: a bad file gives one line on stderr and a
non-zero exit, never a traceback, and no output file (not even a partial or temporary one).

Each case is a fresh ``python -m gonio`` process (seconds each), so the default run takes
:data:`DEFAULT_CLI_CASES` cases and ``-m slow`` :data:`SLOW_CLI_CASES`. The command depends on
the kind: ``info``, ``convert FILE out.brdf.h5`` or ``fit`` (one Lambert start) for tables,
``info`` for RGL and EXR files, ``plan --rig``
for rig files, ``plan --plan`` for plan files, ``render --fitted`` (tiny) for fit results.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.fuzz.corpus import build_corpus
from tests.fuzz.mutate import make_case

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_CLI_CASES = int(os.environ.get("GONIO_FUZZ_CLI_CASES", "8"))
SLOW_CLI_CASES = int(os.environ.get("GONIO_FUZZ_SLOW_CLI_CASES", "200"))
CLI_TIMEOUT_S = 180
TABLE_KINDS = ("native", "merl", "cornell", "alta")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return build_corpus(tmp_path_factory.mktemp("fuzz-cli-corpus"))


def command(kind: str, path: Path, out: Path, index: int) -> tuple[list[str], Path | None]:
    """The gonio arguments for a case, and the output path it would write (or None)."""
    if kind in TABLE_KINDS and index % 3 == 1:
        return ["convert", str(path), str(out / "out.brdf.h5")], out / "out.brdf.h5"
    if kind in TABLE_KINDS and index % 3 == 2:
        args = ["fit", str(path), "--model", "lambert", "--starts", "1", "--no-plots"]
        return [*args, "--out", str(out / "fit")], out / "fit"
    if kind == "rig":
        return ["plan", "--rig", str(path), "--plan", "iso-tiny"], None
    if kind == "plan":
        return ["plan", "--plan", str(path)], None
    if kind == "fit":
        target = out / "render"
        args = ["render", "--fitted", str(path), "--light", "dir:0,0", "--resolution", "8"]
        return [*args, "--spp", "1", "--no-images", "--out", str(target)], target
    return ["info", str(path)], None


def run_cli_case(master: int, index: int, corpus, tmp: Path) -> str | None:
    """Run one case through the CLI; the problem found, or None."""
    case = make_case(master, index, corpus)
    folder = tmp / f"case{index}"
    folder.mkdir()
    path = folder / case.seed.path.name
    path.write_bytes(case.data)
    out = folder / "out"
    out.mkdir()
    args, target = command(case.seed.kind, path, out, index)
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), JAX_PLATFORMS="cpu")
    try:
        p = subprocess.run(
            [sys.executable, "-m", "gonio", *args],
            capture_output=True,
            text=True,
            timeout=CLI_TIMEOUT_S,
            env=env,
            cwd=folder,
        )
    except subprocess.TimeoutExpired:
        return f"gonio {args[0]} ran past {CLI_TIMEOUT_S} s; {case.describe()}"
    err = p.stderr.strip()
    where = f"gonio {' '.join(args[:1])}: {case.describe()}"
    if "Traceback" in p.stderr:
        return f"traceback from {where}\n{err[-600:]}"
    if p.returncode != 0:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        if len(lines) != 1 or not lines[0].startswith("gonio: "):
            return f"exit {p.returncode} without one 'gonio: ' line on stderr from {where}: {err!r}"
        left = sorted(x.name for x in out.iterdir())
        if left:
            return f"failed run left {left} in the output folder; {where}"
    elif target is not None and not target.exists():
        return f"exit 0 but no {target.name}; {where}"
    return None


def _run(master: int, n: int, corpus, tmp: Path) -> None:
    problems = [q for i in range(n) if (q := run_cli_case(master, i, corpus, tmp)) is not None]
    assert not problems, "\n".join(problems)


def test_cli_on_mutated_files(corpus, tmp_path):
    _run(23, DEFAULT_CLI_CASES, corpus, tmp_path)


@pytest.mark.slow
def test_cli_on_mutated_files_slow(corpus, tmp_path):
    _run(2023, SLOW_CLI_CASES, corpus, tmp_path)
