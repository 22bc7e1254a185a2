# `python -m gonio`. The first thing done is to catch SIGINT and SIGTERM, through the C module
# _signal (importing signal.py runs an enum set-up long enough for a Ctrl-C to land in it as a
# KeyboardInterrupt traceback); gonio.interrupts then takes over what arrived.
import _signal

_early: list[int] = []


def _record(signum, frame):
    _early.append(signum)


_signal.signal(_signal.SIGINT, _record)
_signal.signal(_signal.SIGTERM, _record)

import sys  # noqa: E402

from gonio import interrupts  # noqa: E402

interrupts.install(_early, hold=True)

from gonio.cli import main  # noqa: E402

sys.exit(main())
