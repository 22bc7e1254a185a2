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
