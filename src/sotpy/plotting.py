r"""Figures from a :class:`~sotpy.graph.tracer.Tracer` recording, saved as PNG.

::

    tracer = Tracer("tracer")
    tracer.add(ctrl.torque, "torque"); tracer.add(servo.error, "error")
    tracer.add(ctrl.ramps, "ramps"); tracer.setTimeStep(0.001); tracer.start()
    device.after.addSignal(tracer.trigger)
    ...                                                   # run
    plot_tracer(tracer, {"torques (N m)": ["torque"],
                         "hand error (m)": ["error[0:3]"],
                         "activation ramps": ["ramps"]}, "run.png")

The recording is a ``Tracer`` (its :meth:`~sotpy.graph.tracer.Tracer.data`), the path of
the ``.npz`` its ``dump`` wrote, or a mapping of the same form (``"time"`` (n,), one
``(n, width)`` array per column). Each group is one subplot, sharing the time axis
(``time``: seconds if the tracer had ``setTimeStep``, ticks otherwise); a series is a
column label (every component), ``"label[i]"`` (one component) or ``"label[i:j]"``
(components ``i`` to ``j - 1``); the legend names each line ``label[i]`` (``label``
alone for a one-component column). The figure is a :class:`matplotlib.figure.Figure`
built without pyplot (no global state, nothing to close); it is returned so that its
lines can be inspected.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SotpyError

__all__ = ["plot_tracer", "recording"]

_SERIES = re.compile(r"^(?P<label>.+?)(\[(?P<i>-?\d+)(:(?P<j>-?\d*))?\])?$")


def recording(source: Any) -> dict[str, np.ndarray]:
    """The recording of ``source`` (a Tracer, an ``.npz`` path or a mapping) as
    ``{"time": (n,), label: (n, width), ...}``."""
    if hasattr(source, "data") and callable(source.data):
        data = dict(source.data())
    elif isinstance(source, (str, Path)):
        p = Path(source)
        if p.suffix != ".npz" or not p.is_file():
            raise SotpyError(f"plot_tracer: {str(p)!r} is not an .npz file written by Tracer.dump")
        with np.load(p) as z:
            data = {k: z[k] for k in z.files}
    elif isinstance(source, Mapping):
        data = dict(source)
    else:
        what = type(source).__name__
        raise SotpyError(f"plot_tracer: expected a Tracer, an .npz path or a mapping, got {what}")
    if "time" not in data:
        raise SotpyError("plot_tracer: the recording has no 'time' column")
    out = {"time": np.asarray(data["time"], dtype=float).ravel()}
    for k, v in data.items():
        if k in ("time", "tick"):
            continue
        arr = np.asarray(v, dtype=float)
        out[k] = arr.reshape(len(arr), -1) if arr.ndim != 2 else arr
    return out


def _series(data: dict[str, np.ndarray], spec: str) -> list[tuple[str, np.ndarray]]:
    """``[(legend, y)]`` of one series spec (see the module doc)."""
    if spec in data:  # a label that itself ends with [..] wins
        label, i, j = spec, None, None
    else:
        m = _SERIES.match(spec)
        label = m.group("label") if m else spec
        i = m.group("i") if m else None
        j = m.group("j") if m else None
    if label not in data or label == "time":
        cols = [k for k in data if k != "time"]
        raise SotpyError(f"plot_tracer: no column {label!r} in the recording (columns: {cols})")
    arr = data[label]
    width = arr.shape[1]
    if i is None:
        idx = list(range(width))
    elif j is None:
        k = int(i)
        if not -width <= k < width:
            raise SotpyError(
                f"plot_tracer: {spec!r}: component {k} out of range, {label!r} has {width}"
            )
        idx = [k % width]
    else:
        idx = list(range(width))[slice(int(i), int(j) if j else None)]
        if not idx:
            raise SotpyError(f"plot_tracer: {spec!r} selects no component of {label!r} ({width})")
    if width == 1:
        return [(label, arr[:, 0])]
    return [(f"{label}[{k}]", arr[:, k]) for k in idx]


def plot_tracer(
    source: Any,
    groups: Mapping[str, Sequence[str]] | None = None,
    path: str | Path | None = None,
    title: str | None = None,
    xlabel: str | None = None,
    dpi: int = 100,
) -> Any:
    """Plot a recording, one subplot per group, and save it as PNG at ``path``.

    Args:
        source: a ``Tracer``, the path of its ``.npz`` dump, or a mapping like
            ``Tracer.data()``.
        groups: subplot title (used as the y label) -> series specs (``"label"``,
            ``"label[i]"``, ``"label[i:j]"``); default: one subplot per column.
        path: where to save the PNG (None: not saved).
        title: the figure's title.
        xlabel: the time axis' label (default ``"time (s)"`` if the recording has a
            ``tick`` column, i.e. the tracer had a time step, else ``"tick"``).
        dpi: resolution of the PNG.

    Returns:
        The ``matplotlib.figure.Figure``: ``fig.axes[g].lines[s]`` is the ``s``-th line
        of group ``g``, x the time, y the recorded values.

    Raises:
        SotpyError: an unknown column or component, an empty recording or group.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    has_tick = (
        hasattr(source, "data")
        and callable(source.data)
        and getattr(source, "_timeStep", None) is not None
    ) or (isinstance(source, Mapping) and "tick" in source)
    if isinstance(source, (str, Path)) and Path(source).is_file():
        with np.load(source) as z:
            has_tick = "tick" in z.files
    data = recording(source)
    t = data["time"]
    if len(t) == 0:
        raise SotpyError("plot_tracer: the recording is empty (no row recorded)")
    if groups is None:
        groups = {k: [k] for k in data if k != "time"}
    if not groups:
        raise SotpyError("plot_tracer: nothing to plot (no group, no column)")
    fig = Figure(figsize=(8, 2.6 * len(groups)), dpi=dpi)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (name, specs) in zip(axes, groups.items(), strict=True):
        if isinstance(specs, str):
            specs = [specs]
        if not specs:
            raise SotpyError(f"plot_tracer: the group {name!r} has no series")
        for spec in specs:
            for legend, y in _series(data, spec):
                ax.plot(t, y, label=legend)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
        if len(ax.lines) <= 12:
            ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel(xlabel or ("time (s)" if has_tick else "tick"))
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, format="png")
    return fig
