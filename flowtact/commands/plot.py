"""``flowtact plot REC.h5 -o FILE``: plot a recording: each stream as what it is (lines in units, steps, rasters, pulses, frames)."""

from __future__ import annotations

import argparse

from flowtact.commands import Command
from flowtact.errors import UsageError
from flowtact.inputs.limits import cli_finite_seconds

__all__ = ["COMMAND"]


def add_arguments(plot: argparse.ArgumentParser) -> None:
    plot.add_argument("recording", help="an .h5 file written by flowtact run --record")
    plot.add_argument("-o", "--output", required=True, help="image file (.png, .svg, .pdf)")
    plot.add_argument("--streams", nargs="*", help="streams to plot (default: all)")
    plot.add_argument("--from", dest="t0", type=cli_finite_seconds, help="start time (s)")
    plot.add_argument("--to", dest="t1", type=cli_finite_seconds, help="end time (s)")
    from flowtact.commands import entry_point_summary
    from flowtact.pictures.figures import figure_entry_points

    figures = "; ".join(f"{n}: {entry_point_summary(ep)}" for n, ep in figure_entry_points().items())
    plot.add_argument(
        "--figure",
        metavar="NAME",
        help="draw the figure a package registered as NAME instead (entry-point group flowtact.figures; "
        f"installed: {figures or 'none'})",
    )
    plot.add_argument(
        "--paper",
        dest="figure",
        action="store_const",
        const="paper",
        help="the same as --figure paper",
    )


def check(args: argparse.Namespace) -> str | None:
    if args.t0 is not None and args.t1 is not None and not args.t0 < args.t1:
        return f"plot: --from ({args.t0:g}) must be before --to ({args.t1:g})"
    return None


def run(args: argparse.Namespace) -> int:
    from flowtact.errors import NotARecording, RecordingRefused
    from flowtact.pictures.recording_figure import plot_recording

    t_range = None if args.t0 is None and args.t1 is None else (args.t0, args.t1)
    try:
        out = plot_recording(
            args.recording, args.output, streams=args.streams, t_range=t_range, figure=args.figure
        )
    except KeyError as e:  # an unknown --streams name: a usage error
        raise UsageError(str(e.args[0])) from e
    except (RecordingRefused, NotARecording) as e:  # bad input, refused before reading: exit 2
        raise UsageError(str(e)) from e
    print(f"wrote {out}")
    return 0


COMMAND = Command(
    run=run,
    add_arguments=add_arguments,
    check=check,
    description="Plot a recording on a shared time axis: vector samples as labelled lines per channel "
    "in their units (heat map beyond 12 channels), categorical streams as named steps, spike events "
    "as rasters with firing rates, stimulation pulses as pulse trains, frames as a thumbnail strip. "
    "Reads block by block: memory stays bounded whatever the file size. --figure NAME draws a figure "
    "an installed package registered instead (--paper: the one named paper).",
)
