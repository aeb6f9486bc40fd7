"""Play a file back in place of a node, on that node's own output ports: what ``--replay`` builds.

``flowtact run graphs/touch.yaml --replay sensor=log.csv`` swaps node ``sensor`` (an
``aunp_sensor``) for a stand-in that keeps the node's name and its output ports ``r`` and ``ref``,
so edges, ``record:`` names and plots stay as they were. The stand-in's class is made per replaced
block (its ports are that block's) and is reachable as ``flowtact.blocks.signal.replay_ports:BLOCK``,
which is how graphs, workers and recordings name it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

import flowtact.api as ft
from flowtact.blocks.signal.csv_log import CsvError, display, read_csv_log
from flowtact.blocks.signal.replay import SUFFIXES, Replay, h5_streams
from flowtact.blocks.signal.replay_limits import MAX_STREAMS, listing
from flowtact.catalog.blocks import load_block
from flowtact.errors import FileRefused, UnknownBlockError
from flowtact.graphfile.replay_spec import parse_port_map
from flowtact.inputs.bounded_files import open_npz, refusal
from flowtact.params import did_you_mean

__all__ = ["ReplayPorts", "ReplayPortsConfig", "stand_in_class"]

#: Column names a port's channels may take in a CSV, tried in this order: r[0], r.0, r_0.
INDEXED = ("{port}[{i}]", "{port}.{i}", "{port}_{i}")


@dataclass(frozen=True)
class ReplayPortsConfig(ft.Config):
    path: str = ft.param(
        doc="file to play back: a flowtact recording (.h5), a .npz or a .csv log (relative: to the graph file)",
        path=True,
    )
    ports: str = ft.param(
        "",
        doc="PORT=COLUMN[,COLUMN...];... : which columns (.csv), array (.npz) or stream (.h5) feed which "
        "port; ports left out are found by name",
    )
    need: tuple[str, ...] = ft.param((), doc="ports the file must provide (the graph consumes them)")

    def check(self) -> None:
        suffix = Path(self.path).suffix.lower()
        if suffix not in SUFFIXES:
            raise self.error("path", f"must name a {', '.join(SUFFIXES)} file; got {self.path!r}")
        try:
            parse_port_map(self.ports)
        except ValueError as e:
            raise self.error("ports", str(e)) from None


class ReplayPorts:
    """Play a file back in place of a node of another block, on that block's output ports.

    Notes
    -----
    It has the replaced block's output ports, with their declared dtype, shape and units; the rate
    comes from the file's time stamps (or the recording). A port the file does not provide emits
    nothing and has no stream (recording it is skipped, with a note); one listed in ``need`` must be
    there.

    Finding a port's data, unless ``ports`` maps it: in a ``.h5`` recording the stream
    ``<node>.<port>`` (the node's own recorded output); in a ``.npz`` the array named like the port;
    in a ``.csv`` the column named like the port (one value per sample) or the columns ``port[0]``,
    ``port[1]``, ... (also ``port.0`` or ``port_0``), one per channel. A CSV carries no units: the
    port keeps the units its block declares. Each port plays like the ``replay`` block (the file's
    own time stamps as graph time); after the file's end it emits nothing (no held value).

    Example
    -------
    >>> from flowtact.blocks.signal.replay_ports import stand_in_class
    >>> from flowtact.testing import run_source
    >>> cls = stand_in_class("aunp_sensor")
    >>> out = run_source(cls(**cls.example().params), 0.2)
    >>> out["r"].data.shape, out["ref"].data.shape
    ((200, 4), (200,))
    """

    config_cls = ReplayPortsConfig
    replaces: ClassVar[type[ft.Block]]
    counter_docs: ClassVar[dict[str, str]] = {
        "skipped_before_zero": "samples of the file whose time fell before graph time 0: not played",
    }
    node: str
    config: Any
    outputs: ClassVar[dict[str, Any]]
    demanded: frozenset[str]
    seed: int

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)  # type: ignore[call-arg]
        self._players: dict[str, Replay] = {}

    # -- compile time ------------------------------------------------------------------------
    def specs(self, inputs: Any) -> dict[str, ft.StreamSpec]:  # noqa: ARG002 — a source
        """The spec of every port the file provides, checked against the replaced block's ports."""
        if self._players:  # opened for a run: each has read its file
            return {port: player.specs({})["y"] for port, player in self._players.items()}
        return {port: spec for port, (_, spec) in self._new_players().items()}

    def _new_players(self) -> dict[str, tuple[Replay, ft.StreamSpec]]:
        """A replay for every port the file provides, with its spec checked against the replaced block's."""
        players = {}
        for port, source in self._sources().items():
            player = Replay(node=self.node, **self._player_params(port, source))
            try:
                spec = player.specs({})["y"]
            except ft.SpecError as e:
                raise ft.SpecError(None, f"port '{port}': {e}", where=e.where) from None
            except ft.ConfigError as e:
                raise ft.SpecError(
                    None, f"port '{port}': '{e.field}' {e.rule}" if e.field else str(e)
                ) from None
            self._check(port, spec, source)
            players[port] = (player, spec)
        return players

    def _file(self) -> str:
        return display(self.config.path)

    def _sources(self) -> dict[str, str | tuple[str, ...]]:
        """Port -> the file's column(s), array or stream feeding it."""
        c = self.config
        path = Path(c.path)
        if not path.exists() and not path.is_symlink():
            where = "" if path.parent.is_dir() else " (no such folder)"
            raise ft.SpecError(None, f"no such file: {self._file()}{where}")
        suffix = path.suffix.lower()
        try:
            names = self._names(path, suffix)
        except FileRefused as e:
            raise ft.SpecError(None, e.reason, where=(self._file(), 1, 1)) from None
        except OSError as e:  # a dangling link, a file that cannot be read
            raise ft.SpecError(None, refusal(path, e).reason, where=(self._file(), 1, 1)) from None
        known = set(names)
        what = {".csv": "column", ".npz": "array"}.get(suffix, "stream")
        explicit = parse_port_map(c.ports)
        sources: dict[str, str | tuple[str, ...]] = {}
        for port, cols in explicit.items():
            if port not in self.outputs:
                raise ft.SpecError(
                    None,
                    f"'{port}' is not an output of {self.replaces.name}{did_you_mean(port, self.outputs)}",
                )
            if suffix != ".csv" and len(cols) != 1:
                raise ft.SpecError(
                    None, f"port '{port}': a {suffix} file feeds a port from one {what}; got {cols}"
                )
            for col in cols:
                if col not in known:
                    close = did_you_mean(col, names) if names else ""
                    close = close if close.startswith(" (did") else ""
                    raise ft.SpecError(
                        None,
                        f"port '{port}': no {what} '{col}' in {self._file()}{close}"
                        f" ({what}s: {listing(names)})",
                    )
            sources[port] = cols if suffix == ".csv" else cols[0]
        for port in self.outputs:
            if port not in sources and (found := self._by_name(port, suffix, known)) is not None:
                sources[port] = found
        missing = [p for p in c.need if p not in sources]
        if missing:
            example = ";".join(f"{p}={self._placeholder(p, what)}" for p in missing)
            raise ft.SpecError(
                None,
                f"{self._file()} has no {what} for port{'s' if len(missing) > 1 else ''} "
                f"{', '.join(repr(p) for p in missing)} of {self.replaces.name} ({what}s: "
                f"{listing(names)}); {'map them' if what == 'stream' else f'name {what}s after the ports or map them'}: "
                f"--replay '{self.node}={self._file()}:{example}'",
            )
        return sources

    def _placeholder(self, port: str, what: str) -> str:
        """``C1,C2,C3,C4`` for a port of 4 channels, ``COLUMN`` for one value (in a hint)."""
        shape = self.outputs[port].shape
        if what == "column" and shape is not None and len(shape) == 1:
            return ",".join(f"C{i + 1}" for i in range(shape[0]))
        return what.upper()

    def _names(self, path: Path, suffix: str) -> list[str]:
        """The columns (without ``t``), arrays or streams the file holds."""
        if suffix == ".csv":
            try:
                return list(read_csv_log(path).data_columns)
            except CsvError as e:
                raise ft.SpecError(None, e.message, where=e.where) from None
        if suffix == ".npz":
            with open_npz(path, MAX_STREAMS) as z:
                return [n for n in z.names if n != "t"]
        return list(h5_streams(path))

    def _by_name(self, port: str, suffix: str, names: set[str]) -> str | tuple[str, ...] | None:
        if suffix in (".h5", ".hdf5"):
            stream = f"{self.node}.{port}"
            return stream if stream in names else None
        if port in names:
            return (port,) if suffix == ".csv" else port
        if suffix != ".csv":
            return None
        for style in INDEXED:
            cols = []
            while (col := style.format(port=port, i=len(cols))) in names:
                cols.append(col)
            if cols:
                return tuple(cols)
        return None

    def _player_params(self, port: str, source: str | tuple[str, ...]) -> dict[str, Any]:
        declared = self.outputs[port]
        params: dict[str, Any] = {"path": self.config.path}
        # CSV columns: one column gives a value per sample, unless the port is a vector
        if isinstance(source, tuple):
            one = len(source) == 1 and (declared.shape is None or tuple(declared.shape) == ())
            params["stream"] = source[0] if one else list(source)
        else:
            params["stream"] = source
        if Path(self.config.path).suffix.lower() in (".csv", ".npz"):
            params["units"] = declared.units or "1"
        return params

    def _check(self, port: str, spec: ft.StreamSpec, source: str | tuple[str, ...]) -> None:
        """The played stream must be what the replaced block's port declares (rate aside)."""
        declared = self.outputs[port]
        block = self.replaces.name
        given = f"{', '.join(source)}" if isinstance(source, tuple) else source
        given = f"'{given}' in {self._file()}"
        if declared.events != spec.events:
            kind = "an event stream" if declared.events else "a sample stream"
            hint = "; replay it from a .h5 recording" if declared.events else ""
            raise ft.SpecError(None, f"port '{port}' of {block} is {kind}, {given} is not{hint}")
        if declared.shape is not None and tuple(declared.shape) != tuple(spec.shape):
            n = int(np.prod(declared.shape)) if declared.shape else 1
            cols = (
                f" ({n} column{'s' if n != 1 else ''})"
                if isinstance(source, tuple) and len(declared.shape) < 2
                else ""
            )
            raise ft.SpecError(
                None,
                f"port '{port}' of {block} takes samples of shape {tuple(declared.shape)}{cols}; "
                f"{given} gives {tuple(spec.shape)}",
            )
        if declared.dtype is not None and declared.dtype != spec.dtype:
            raise ft.SpecError(
                None, f"port '{port}' of {block} carries {declared.dtype}; {given} is {spec.dtype}"
            )
        if declared.units is not None and declared.units != spec.units:
            raise ft.SpecError(
                None, f"port '{port}' of {block} is in '{declared.units}'; {given} is in '{spec.units}'"
            )

    def ends_at(self, inputs: Any) -> float | None:  # noqa: ARG002 — a source: its end comes from its file
        """The latest end of the played ports (None: nothing to play)."""
        players = self._players or {port: player for port, (player, _) in self._new_players().items()}
        ends = [e for p, r in players.items() if p in self.demanded and (e := r.ends_at({})) is not None]
        return max(ends, default=None)

    # -- run time ----------------------------------------------------------------------------
    def reset(self) -> None:
        self._played: dict[str, list[float]] = {}  # port -> [count, first t, last t] (for summary)
        if not self._players:
            self._players = {port: player for port, (player, _) in self._new_players().items()}
        for port, player in self._players.items():
            if port in self.demanded:
                player.bind({}, seed=self.seed)
                self.count("skipped_before_zero", player.counters.get("skipped_before_zero", 0))  # type: ignore[attr-defined]

    def open(self) -> None:
        """Open the file for each played port (an .h5 stays open, read slice by slice)."""
        for port, player in self._players.items():
            if port in self.demanded:
                player.open()

    def close(self) -> None:
        """Close what ``open`` opened."""
        for player in getattr(self, "_players", {}).values():
            player.close()

    def step(self, now: float) -> dict[str, ft.Chunk]:
        out = {p: r(now)["y"] for p, r in self._players.items() if p in self.demanded}
        for p, chunk in out.items():
            if len(chunk.t):
                seen = self._played.setdefault(p, [0, float(chunk.t[0]), 0.0])
                seen[0] += len(chunk.t)
                seen[2] = float(chunk.t[-1])
        return out

    def summary(self) -> str | None:
        """``replayed FILE (r: 3,000 samples, 0-2.999 s)``: what the run played back, per port."""
        parts = [
            f"{p}: {n:,} {'events' if self._players[p].output_specs['y'].events else 'samples'}, "
            f"{t0:g}-{t1:g} s"
            for p, (n, t0, t1) in self._played.items()
        ]
        return f"replayed {self._file()} ({'; '.join(parts) or 'nothing: no sample fell in the run'})"

    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(params={"path": str(_example_csv(cls.replaces))}, rate_hz=1000.0, duration_s=0.4)


@functools.cache
def stand_in_class(block: str) -> type[ft.Source]:
    """The replay class standing in for nodes of ``block`` (a registered name or ``module:Class``)."""
    replaced = load_block(block)
    if issubclass(replaced, ReplayPorts):  # replaying a replay: the same ports, the same class
        return replaced
    ports = ", ".join(replaced.outputs) or "none"
    return type(
        f"ReplayAs{replaced.__name__}",
        (ReplayPorts, ft.Source),
        {
            "__module__": __name__,
            "__doc__": f"Play a file back in place of a node of {replaced.name}, on its ports ({ports}).\n"
            + (ReplayPorts.__doc__ or "").partition("\n")[2],
            "outputs": dict(replaced.outputs),
            "replaces": replaced,
            "name": "replay",
        },
    )


def __getattr__(name: str) -> type[ft.Source]:
    """``replay_ports:aunp_sensor`` (as the graph names the stand-in) -> its class."""
    if name.startswith("__"):
        raise AttributeError(name)
    try:
        return stand_in_class(name)
    except UnknownBlockError as e:
        raise AttributeError(f"no stand-in replay for block '{name}': {e}") from None


def _example_csv(block: type[ft.Block]) -> Path:
    """0.4 s at 1 kHz of every fixed-shape sample port of ``block``, columns named as found by
    default, in this process's private example folder (:func:`flowtact.block.example_folder`)."""
    path = ft.example_folder() / f"replay-ports-{block.name}.csv"
    if not path.exists():
        t = np.arange(400) / 1000.0
        cols: dict[str, np.ndarray] = {"t": t}
        for k, (port, p) in enumerate(block.outputs.items()):
            if p.events or p.shape is None or len(p.shape) > 1:
                continue
            n = p.shape[0] if p.shape else 0
            for i in range(max(n, 1)):
                name = f"{port}[{i}]" if n else port
                cols[name] = np.round(np.sin(2 * np.pi * (3 + k) * t + i), 6)
        np.savetxt(
            path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments=""
        )
    return path
