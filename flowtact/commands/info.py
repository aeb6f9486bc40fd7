"""``flowtact info REC.h5``: describe a recording and verify its checksums."""

from __future__ import annotations

import argparse
import json

from flowtact.commands import Command
from flowtact.console.command import EXIT_RUN_ERROR
from flowtact.errors import UsageError

__all__ = ["COMMAND"]


def add_arguments(info: argparse.ArgumentParser) -> None:
    info.add_argument("recording", help="an .h5 file written by flowtact run --record")
    info.add_argument("--json", action="store_true", help="print the report as JSON")


def run(args: argparse.Namespace) -> int:
    from flowtact.errors import NotARecording, RecordingRefused
    from flowtact.recording.info import format_info, inspect_recording

    try:
        info = inspect_recording(args.recording)
    except (RecordingRefused, NotARecording) as e:  # bad input, refused before reading: exit 2
        raise UsageError(str(e)) from e
    print(json.dumps(info.to_dict(), indent=2) if args.json else format_info(info))
    return 0 if info.ok else EXIT_RUN_ERROR


COMMAND = Command(run=run, add_arguments=add_arguments)
