import subprocess
import sys

from gonio import __version__
from gonio.cli import main


def test_version(capsys):
    try:
        main(["--version"])
    except SystemExit as exc:
        assert exc.code == 0
    assert __version__ in capsys.readouterr().out


def test_help_runs_as_console_script():
    out = subprocess.run(
        [sys.executable, "-m", "gonio", "--help"], capture_output=True, text=True, check=True
    )
    assert "usage: gonio" in out.stdout
    assert "Traceback" not in out.stderr


def test_gonio_error_becomes_one_line(monkeypatch, capsys):
    import argparse

    from gonio import cli
    from gonio.errors import FormatError

    def register(sub):
        p = sub.add_parser("boom")

        def run(args: argparse.Namespace) -> int:
            raise FormatError("x.brdf: truncated at byte 12")

        p.set_defaults(func=run)

    class Fake:
        pass

    fake = Fake()
    fake.register = register
    monkeypatch.setattr(cli, "COMMAND_MODULES", ("fake_mod",))
    monkeypatch.setitem(sys.modules, "fake_mod", fake)
    rc = cli.main(["boom"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err == "gonio: x.brdf: truncated at byte 12\n"


def test_lazy_help_matches_each_modules_own_help():
    import argparse
    import importlib

    from gonio.cli import LAZY_COMMANDS

    for name, (module, text) in LAZY_COMMANDS.items():
        parser = argparse.ArgumentParser()
        sub = parser.add_subparsers()
        importlib.import_module(module).register(sub)
        helps = {a.dest: a.help for a in sub._choices_actions}
        assert helps.get(name) == text, (name, helps.get(name))


def test_help_and_rig_list_import_no_heavy_library():
    code = (
        "import sys\nfrom gonio.cli import main\n"
        "for argv in (['--help'], ['rig', 'list']):\n"
        "    try:\n        main(argv)\n    except SystemExit:\n        pass\n"
        "print(sorted(m for m in ('jax', 'scipy', 'matplotlib') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout


def test_every_command_still_parses_its_options(capsys):
    # The command is imported on demand; its own options and --help work as before.
    try:
        main(["grid", "--help"])
    except SystemExit as exc:
        assert exc.code == 0
    assert "--method" in capsys.readouterr().out
