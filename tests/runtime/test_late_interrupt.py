"""A Ctrl-C that arrives as a finished command exits does not change its exit status (0, not -2)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: The console script's own shape (``sys.exit(main())``), with SIGINT sent once main has returned:
#: the moment a user's Ctrl-C meets a run that has printed its summary and is exiting.
LATE_SIGINT = textwrap.dedent(
    """
    import os, signal, sys
    from flowtact.cli import main
    sys.argv = ["flowtact", *sys.argv[1:]]
    status = main()
    os.kill(os.getpid(), signal.SIGINT)
    sys.exit(status)
    """
)


@pytest.mark.parametrize(
    "argv",
    [
        ["validate", str(ROOT / "graphs" / "touch.yaml")],
        ["run", str(ROOT / "graphs" / "touch.yaml"), "--fast", "--duration", "0.2", "--inproc"],
    ],
    ids=["validate", "run"],
)
def test_sigint_at_the_moment_of_exit_gives_the_commands_status(argv):
    done = subprocess.run(
        [sys.executable, "-c", LATE_SIGINT, *argv], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert "KeyboardInterrupt" not in done.stderr


def test_in_process_calls_leave_ctrl_c_alone():
    import signal

    from flowtact.cli import main

    before = signal.getsignal(signal.SIGINT)
    assert main(["validate", str(ROOT / "graphs" / "touch.yaml")]) == 0
    assert signal.getsignal(signal.SIGINT) is before
