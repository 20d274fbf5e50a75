"""The ``Tracer`` entity: records signals into preallocated memory, writes npz/CSV or
SoT's text files.

Usage, as with SoT's ``TracerRealTime``::

    tracer = Tracer("tracer")
    tracer.add("IP.state")                    # or a signal object; optional column name
    tracer.setBufferSize(10_000)               # rows, allocated at the first record
    tracer.start()
    device.after.addSignal(tracer.trigger)     # or tracer.trigger.recompute(t) each tick
    ...
    tracer.dump("run.npz")                     # or "run.csv"

Reading ``trigger`` at tick ``t`` reads every traced signal at ``t`` (computing it if
outdated) and appends one row. ``trigger.setPeriod(k)`` records every ``k`` ticks.
``triger`` (SoT's spelling) is the same trigger: reading either records the row once.

SoT's files. ``open(dir, prefix, suffix)`` names one text file per traced signal,
``dir/prefix + name + suffix`` (``name`` the label given to ``add``, else the signal's
short name), created empty at once; ``dump()`` then appends the rows recorded since the
last ``dump()`` to them and forgets those rows (``TracerRealTime``'s dump), one line per
row: the tick, a tab, the values separated by tabs (a matrix or a placement row after
row), written with 17 significant digits. ``close()`` dumps what is left and closes the
files. ``empty()`` forgets the rows, ``clear()`` also forgets the traced signals and
closes the files (SoT's ``clear``).

When the buffer is full the tracer never drops data silently: with the default
``overflow="stop"`` it stops recording, warns once (:class:`~sotpy.errors.SotpyWarning`),
counts the rows it could not keep (``dropped``) and shows ``FULL`` in its status; with
``"ring"`` it keeps the newest rows, warns once and counts the overwritten ones; with
``"raise"`` it raises :class:`~sotpy.errors.TracerOverflow`.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

from ..errors import SignalTypeError, SotpyError, SotpyWarning, TracerOverflow
from .command import command
from .entity import Entity, Output
from .pool import pool
from .signal import Signal
from .types import INT

__all__ = ["Tracer"]

_OVERFLOW = ("stop", "ring", "raise")


class Tracer(Entity):
    """Record chosen signals every tick (or every k ticks) into a bounded buffer."""

    def __init__(self, name: str, bufferSize: int = 100_000, overflow: str = "stop") -> None:
        self._columns: list[tuple[str, Signal]] = []
        self._fileNames: list[str] = []  # per column: the name of its SoT file
        self._files: list[Path] | None = None  # the files open() named, if open
        self._size = 0
        self.setBufferSize(bufferSize)
        self.setOverflow(overflow)
        self._recording = False
        self._timeStep: float | None = None
        self.empty()

    @Output(INT, withTime=True, timeDependent=True, doc="number of rows recorded")
    def trigger(self, t: int, *values: Any) -> int:
        """Reads the traced signals at t and records one row."""
        if self._recording:
            self._record(t, values)
        return self._count

    @Output(INT, deps=("trigger",), doc="SoT's spelling of trigger: reading it records")
    def triger(self, count: int) -> int:
        """The same row count as ``trigger``, which it reads (SoT's name)."""
        return count

    # -- configuration ----------------------------------------------------------------
    @command
    def add(self, signal: Signal | str, name: str | None = None) -> None:
        """Trace ``signal`` (a signal or ``"entity.signal"``) under ``name`` (default:
        the signal's path)."""
        sig = pool.getSignal(signal) if isinstance(signal, str) else signal
        if sig.type.to_array is None and sig.type.name != "any":
            raise SignalTypeError(
                f"{self.className}({self.name}).add: cannot trace {sig.name}: "
                f"{sig.type.name} values have no numeric form"
            )
        label = name or sig.path
        if label in self.columns():
            raise SotpyError(f"{self.className}({self.name}).add: {label!r} is already traced")
        if self._count:
            raise SotpyError(
                f"{self.className}({self.name}).add: empty() the {self._count} recorded rows "
                "(or dump() them) before changing the traced signals"
            )
        fileName = name or sig.shortName
        if self._files is not None:
            path = self._filePath(fileName)
            self._create(path)
        self.trigger.setDependencies([*self.trigger.dependencies, sig])
        self._columns.append((label, sig))
        self._fileNames.append(fileName)
        if self._files is not None:
            self._files.append(path)
        self._buffers = None

    def columns(self) -> list[str]:
        """Labels of the traced signals, in column order."""
        return [label for label, _ in self._columns]

    @command
    def remove(self, name: str) -> None:
        """Stop tracing the column called ``name``."""
        for i, (label, _sig) in enumerate(self._columns):
            if label == name:
                if self._count:
                    raise SotpyError(
                        f"{self.className}({self.name}).remove: empty() the recorded rows "
                        "(or dump() them) before changing the traced signals"
                    )
                del self._columns[i]
                del self._fileNames[i]
                if self._files is not None:
                    del self._files[i]
                self.trigger.setDependencies([s for _, s in self._columns])
                self._buffers = None
                return
        raise SotpyError(f"{self.className}({self.name}).remove: {name!r} is not traced")

    @command
    def setBufferSize(self, rows: int) -> None:
        """Capacity in rows (ticks recorded); allocated at the first record."""
        if rows < 1:
            raise SotpyError(f"{self.className}({self.name}): buffer size must be >= 1, got {rows}")
        if getattr(self, "_count", 0):
            raise SotpyError(
                f"{self.className}({self.name}).setBufferSize: empty() the recorded rows first"
            )
        self._size = rows
        self._buffers = None

    @command
    def setOverflow(self, policy: str) -> None:
        """What a full buffer does: ``stop`` (default), ``ring`` or ``raise``."""
        if policy not in _OVERFLOW:
            raise SotpyError(
                f"{self.className}({self.name}): overflow policy must be one of "
                f"{', '.join(_OVERFLOW)}, got {policy!r}"
            )
        self._overflow = policy

    @command
    def setTimeStep(self, dt: float) -> None:
        """Write the ``time`` column in seconds (tick * dt) instead of ticks."""
        if not dt > 0:
            raise SotpyError(f"{self.className}({self.name}): time step must be > 0, got {dt}")
        self._timeStep = dt

    @command
    def start(self) -> None:
        """Record at each trigger."""
        if not self._columns:
            raise SotpyError(f"{self.className}({self.name}).start: no signal to trace; add() one")
        self._recording = True

    @command
    def stop(self) -> None:
        """Stop recording (the buffer is kept)."""
        self._recording = False

    @command
    def empty(self) -> None:
        """Forget the recorded rows and the overflow state (the traced signals stay)."""
        self._count = 0
        self._head = 0
        self.dropped = 0
        self.full = False
        if not hasattr(self, "_ticks"):  # the buffers are kept for the next rows
            self._buffers: list[Any] | None = None
            self._ticks: Any = None

    @command
    def clear(self) -> None:
        """Forget the traced signals and their rows, and close the files (SoT's
        ``clear``; rows not dumped are lost: ``close()`` first to keep them)."""
        self._files = None
        self._columns = []
        self._fileNames = []
        self._buffers = None
        self.trigger.setDependencies([])
        self.empty()

    # -- SoT's files ------------------------------------------------------------------
    @command
    def open(self, dirname: str, prefix: str, suffix: str) -> None:
        """Write SoT's text files: one per traced signal, ``dirname/prefix + name +
        suffix``, created empty now (and for a signal added later, when it is added);
        ``dump()`` appends the recorded rows to them. The directory is created if needed.
        Reopening first ``close()`` s the files open."""
        if self._files is not None:
            self.close()
        d = Path(dirname).expanduser()
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SotpyError(
                f"{self.className}({self.name}).open: cannot create the directory {str(d)!r}: {exc}"
            ) from None
        self._dir, self._prefix, self._suffix = d, prefix, suffix
        paths = [self._filePath(n) for n in self._fileNames]
        for p in paths:
            self._create(p)
        self._files = paths

    def files(self) -> list[str]:
        """The paths of the open files, one per traced signal in column order (empty
        when no file is open)."""
        return [str(p) for p in self._files or []]

    def _filePath(self, fileName: str) -> Path:
        return self._dir / f"{self._prefix}{fileName}{self._suffix}"

    def _create(self, path: Path) -> None:
        try:
            path.write_text("")
        except OSError as exc:
            raise SotpyError(
                f"{self.className}({self.name}): cannot create the trace file {str(path)!r}: {exc}"
            ) from None

    @command
    def close(self) -> None:
        """Dump the rows not yet written to the open files, then close them (nothing
        happens when no file is open)."""
        if self._files is None:
            return
        self._dumpFiles()
        self._files = None

    # -- recording --------------------------------------------------------------------
    def _allocate(self, values: tuple[Any, ...]) -> None:
        import numpy as np

        self._ticks = np.empty(self._size, dtype=np.int64)
        self._buffers = [
            np.empty((self._size, self._width(label, sig, v).size))
            for (label, sig), v in zip(self._columns, values, strict=True)
        ]

    def _width(self, label: str, sig: Signal, v: Any) -> Any:
        import numpy as np

        conv = sig.type.to_array
        try:
            return conv(v) if conv is not None else np.asarray(v, dtype=float).ravel()
        except (TypeError, ValueError):
            raise SignalTypeError(
                f"{self.className}({self.name}): cannot record {sig.name} ({label}): "
                f"value {v!r} is not numeric"
            ) from None

    def _record(self, t: int, values: tuple[Any, ...]) -> None:
        if self._buffers is None:
            self._allocate(values)
        row = self._head
        if self._count == self._size:  # full
            if self._overflow == "raise":
                raise TracerOverflow(
                    f"{self.className}({self.name}): buffer of {self._size} rows is full at "
                    f"tick {t}; dump() and empty(), or setBufferSize()"
                )
            if not self.full:
                self.full = True
                what = (
                    "stopped recording"
                    if self._overflow == "stop"
                    else "overwrites the oldest rows"
                )
                warnings.warn(
                    f"{self.className}({self.name}): buffer of {self._size} rows is full at tick "
                    f"{t}; it {what} (see .dropped)",
                    SotpyWarning,
                    stacklevel=2,
                )
            self.dropped += 1  # a row not kept ("stop") or overwritten ("ring")
            if self._overflow == "stop":
                return
            if row == self._size:
                row = 0
        self._ticks[row] = t
        for (label, sig), buf, v in zip(self._columns, self._buffers, values, strict=True):  # type: ignore[arg-type]
            a = self._width(label, sig, v)
            if a.size != buf.shape[1]:
                raise SignalTypeError(
                    f"{self.className}({self.name}): {sig.name} ({label}) changed size from "
                    f"{buf.shape[1]} to {a.size} at tick {t}"
                )
            buf[row] = a
        self._head = row + 1
        self._count = min(self._count + 1, self._size)

    # -- reading and writing ----------------------------------------------------------
    def data(self) -> dict[str, Any]:
        """The recorded rows, oldest first: ``{"time": (n,), label: (n, width), ...}``;
        ``tick`` holds the ticks when ``time`` is in seconds."""
        import numpy as np

        n = self._count
        if self._buffers is None or n == 0:
            out = {"time": np.empty(0)}
            out.update({label: np.empty((0, 0)) for label, _ in self._columns})
            return out
        if self.full and self._overflow == "ring":
            order = np.r_[self._head : self._size, 0 : self._head]
        else:
            order = np.arange(n)
        ticks = self._ticks[order]
        out: dict[str, Any] = {}
        if self._timeStep is not None:
            out["time"] = ticks * self._timeStep
            out["tick"] = ticks.copy()
        else:
            out["time"] = ticks.copy()
        for (label, _), buf in zip(self._columns, self._buffers, strict=True):
            out[label] = buf[order].copy()
        return out

    @command
    def dump(self, path: str | None = None) -> str:
        """Write the rows to ``path``: ``.npz`` (one array per column) or ``.csv`` (a
        header, ``time`` first, one column per component: ``label[i]``); the rows are
        kept. Without ``path`` (SoT's ``dump()``): append the rows to the files
        ``open`` named and forget them; returns the directory."""
        import numpy as np

        if path is None:
            if self._files is None:
                raise SotpyError(
                    f"{self.className}({self.name}).dump: no file is open: call "
                    "open(dirname, prefix, suffix) first, or dump(path) to a .npz or .csv file"
                )
            self._dumpFiles()
            return str(self._dir)
        p = Path(path)
        data = self.data()
        if p.suffix == ".npz":
            np.savez(p, **data)
        elif p.suffix == ".csv":
            header = ["time"]
            cols = [data["time"].reshape(-1, 1)]
            for label, _ in self._columns:
                arr = data[label]
                width = arr.shape[1]
                header.extend([label] if width == 1 else [f"{label}[{i}]" for i in range(width)])
                cols.append(arr)
            table = np.hstack(cols) if len(data["time"]) else np.empty((0, len(header)))
            np.savetxt(p, table, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
        else:
            raise SotpyError(
                f"{self.className}({self.name}).dump: unknown format {p.suffix!r}; use .npz or .csv"
            )
        return str(p)

    def _dumpFiles(self) -> None:
        """Append the recorded rows to the open files (tick, tab, values), then forget
        them."""
        import numpy as np

        ticks = self._orderedTicks()
        if ticks is not None and len(ticks):
            data = self.data()
            for (label, _), path in zip(self._columns, self._files, strict=True):  # type: ignore[arg-type]
                table = np.column_stack((ticks, data[label]))
                fmt = ["%d"] + ["%.17g"] * data[label].shape[1]
                try:
                    with path.open("a") as f:
                        np.savetxt(f, table, fmt=fmt, delimiter="\t")
                except OSError as exc:
                    raise SotpyError(
                        f"{self.className}({self.name}).dump: cannot write {str(path)!r}: {exc}; "
                        "the rows are kept"
                    ) from None
        self.empty()

    def _orderedTicks(self) -> Any:
        """The recorded ticks, oldest first (None before the first record)."""
        import numpy as np

        if self._buffers is None or self._count == 0:
            return None
        if self.full and self._overflow == "ring":
            order = np.r_[self._head : self._size, 0 : self._head]
        else:
            order = np.arange(self._count)
        return self._ticks[order]

    def status(self) -> str:
        """One line: rows recorded, capacity, FULL and dropped rows."""
        state = "recording" if self._recording else "stopped"
        full = f", FULL, {self.dropped} rows dropped" if self.full else ""
        files = f", files {self._dir}/{self._prefix}*{self._suffix}" if self._files else ""
        return f"{self.name}: {state}, {self._count}/{self._size} rows{full}{files}"

    def signalsDisplay(self) -> str:
        return super().signalsDisplay() + "\n" + self.status()
