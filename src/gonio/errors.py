"""Typed exceptions raised by gonio library code.

Every error that bad *input* can cause derives from :class:`GonioError`. The command line catches
``GonioError``, prints ``gonio: <message>`` on one line to stderr and exits with the error's
``exit_code``. An ``OSError`` (the system refusing a file operation: a read-only folder, a
full disk, a file where a folder is needed) is printed the same way, as ``gonio: <path>:
<reason>`` with exit status 1; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class GonioError(Exception):
    """Base class of all expected gonio errors (bad input, refused operations, device faults)."""

    exit_code: int = 1


class ParameterError(GonioError, ValueError):
    """A model or command parameter is out of its documented range or has the wrong shape."""

    exit_code = 2


class FormatError(GonioError, ValueError):
    """A file is malformed, truncated, of an unknown version, or not the format it claims to be."""

    exit_code = 2


class RigConfigError(GonioError, ValueError):
    """A rig file is invalid: a missing or mistyped key, an impossible value."""

    exit_code = 2


class PlanError(GonioError, ValueError):
    """An acquisition plan asks for something the rig cannot do (out of limits, occluded pose)."""

    exit_code = 2


class DeviceError(GonioError, RuntimeError):
    """A device (servo bus, camera, light) failed and could not be recovered by retrying."""

    exit_code = 3


class FrameError(DeviceError):
    """One configuration's frame cannot be measured although the devices work: the holder's
    board is not found in it, or the sample or the white reference is outside it. The run
    engine retakes the frame once, then skips the configuration (journaled as rejected, with
    this message as the reason) instead of stopping the run."""


class FitError(GonioError, RuntimeError):
    """A fit cannot be carried out on this data (too few samples, no valid cells, ...)."""

    exit_code = 4


class Interrupted(KeyboardInterrupt):
    """A run stopped on SIGINT or SIGTERM (``signum``); the CLI exits with 128 + signum.

    A :class:`KeyboardInterrupt`, so code that stops on Ctrl-C stops on it too.
    """

    def __init__(self, message: str = "interrupted", signum: int = 2) -> None:
        super().__init__(message)
        self.signum = signum


class StorageError(GonioError, OSError):
    """A file could not be written because of where it lives, not what it holds: the
    filesystem is full (``ENOSPC``), a quota is exhausted (``EDQUOT``), a file-size limit is
    reached (``EFBIG``), the filesystem is read-only (``EROFS``) or failing (``EIO``), or a run
    folder was removed under a running acquisition. The message names the file and the
    filesystem (its mount point); ``errno`` is the system's error number where there is one.
    Nothing partial is left under the output's name; an acquisition keeps every sample it
    committed and continues with ``gonio acquire --resume RUN`` once space is freed."""

    exit_code = 5


class InUseError(GonioError):
    """A run folder or a serial port is held by another process (its PID is in the message):
    a run folder by the acquisition writing it, a port by the process driving it."""

    exit_code = 6
