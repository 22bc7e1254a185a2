"""gonio.interrupts: a signal is a flag first; the exception is raised only where it cannot be
lost (issue 18, item 8: JAX's gc callback swallowed a KeyboardInterrupt)."""

from __future__ import annotations

import gc
import os
import signal
import time

import pytest

from gonio import interrupts
from gonio.errors import Interrupted


def test_signal_inside_a_gc_callback_is_delivered_after_it(capsys):
    sent = []

    def callback(phase, info):  # stands for jax's _xla_gc_callback
        if phase == "start" and not sent:
            sent.append(1)
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # the handler runs at one of these bytecodes
                pass

    with interrupts.installed() as flag:
        gc.callbacks.append(callback)
        try:
            with pytest.raises(Interrupted, match=r"interrupted \(SIGINT\)"):
                gc.collect()
                time.sleep(1.0)  # redelivered from a timer thread within a few ms
            assert flag.count == 1  # one signal, delivered once more, counted once
        finally:
            gc.callbacks.remove(callback)
    assert "Exception ignored" not in capsys.readouterr().err


def test_shielded_records_and_deferred_raises_on_the_second():
    # the handler this process started with: SIG_IGN when launched in the background by a shell
    before = signal.getsignal(signal.SIGINT)
    with interrupts.installed() as flag:
        with flag.shielded():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.01)
            assert flag.count == 1 and flag.signum == signal.SIGTERM
        flag.reset()
        with flag.shielded(), flag.deferred():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.01)
            assert flag.requested
            with pytest.raises(Interrupted):
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.5)
            assert flag.count == 2
    assert not flag.installed and flag.count == 0
    assert signal.getsignal(signal.SIGINT) is before
