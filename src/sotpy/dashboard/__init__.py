"""A live web dashboard generated from the graph (``sotpy shell --ui``, ``sotpy serve
--ui``, ``sotpy demo ... --ui``, or ``Dashboard(loop)`` in a script).

The page shows the graph (entities, signals, plugs, types; the signals computed at the
last tick; the unplugged inputs the control needs), live plots of any signal, the
stack (each SOT level's residual, rank and active rows; the torque controller's tasks,
weights and ramps), the robot in 3-D (a :class:`~sotpy.viewer.RobotViewer`), and edits
(constants, gains, tasks pushed or removed, the loop started, stopped or stepped) that go
through the shell's path: each holds ``pool.lock`` between two ticks, and a refused one
shows the :mod:`sotpy.errors` message. ``docs/dashboard.md`` is the user's page.

- :mod:`sotpy.dashboard.server`: :class:`Dashboard`, the Tornado server and its token rule;
- :mod:`sotpy.dashboard.model`: the graph's snapshot, the status, the edits, the recorder;
- :mod:`sotpy.dashboard.browser`: headless Chromium driving the page (tests, screenshots).
"""

from .model import Recorder, applyEdit, graphSnapshot, status
from .server import Dashboard, isLoopback

__all__ = ["Dashboard", "Recorder", "applyEdit", "graphSnapshot", "isLoopback", "status"]
