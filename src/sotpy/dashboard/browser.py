"""Headless Chromium on a page: evaluate JavaScript, click, take screenshots.

The dashboard's tests, its benchmark and its documentation's screenshots drive a real
browser with it::

    with HeadlessPage(ui.url(), width=1600, height=1000) as page:
        page.waitFor("document.querySelectorAll('[data-entity]').length > 0")
        page.evaluate("document.title")
        page.screenshot("dashboard.png")

Chromium is the one :func:`sotpy.viewer.findChromium` finds (``bash
tools/install-browser.sh`` installs Debian's), started with the viewer's flags
(headless, no sandbox, WebGL in software, nothing fetched but the page) and driven
through the DevTools protocol over a pipe, with the viewer's client.
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ..errors import SotpyError
from ..loop import _checkedCpus
from ..viewer import _TRAMPOLINE, CHROMIUM_FLAGS, _Devtools, _endSession, _log, findChromium

__all__ = ["HeadlessPage"]


class HeadlessPage:
    """A headless Chromium showing ``url`` (``width`` x ``height`` pixels) until
    :meth:`close`. Every call raises :class:`~sotpy.errors.SotpyError` after
    ``timeout`` s in all (from the start). ``cpus``: the CPUs Chromium and all its
    processes run on (None: any), e.g. a pinned loop's :meth:`~sotpy.loop.ControlLoop.otherCpus`
    so that the browser keeps off the loop's CPU."""

    def __init__(
        self,
        url: str,
        width: int = 1600,
        height: int = 1000,
        timeout: float = 120.0,
        cpus: Iterable[int] | None = None,
    ):
        cpus = _checkedCpus("HeadlessPage", cpus)  # as a loop's: CPUs of this machine
        # the CPUs are set before Chromium starts: every process it starts inherits them
        pin = "" if cpus is None else f"import os; os.sched_setaffinity(0, {sorted(cpus)}); "
        exe = findChromium()
        if exe is None:
            raise SotpyError(
                "HeadlessPage: no Chromium found; install it with 'bash tools/install-browser.sh'"
            )
        self._who = "HeadlessPage"
        self._profile = tempfile.mkdtemp(prefix="sotpy-chromium-")
        to_r, to_w = os.pipe()
        from_r, from_w = os.pipe()
        child_in = fcntl.fcntl(to_r, fcntl.F_DUPFD, 10)
        child_out = fcntl.fcntl(from_w, fcntl.F_DUPFD, 10)
        for fd in (to_r, from_w):
            os.close(fd)
        self._fds = [to_w, from_r]
        self._stderr = open(Path(self._profile) / "stderr.log", "wb")  # noqa: SIM115
        args = [
            *CHROMIUM_FLAGS,
            f"--user-data-dir={self._profile}",
            f"--window-size={width},{height}",
            "--remote-debugging-pipe",
            "about:blank",
        ]
        self._proc: subprocess.Popen[bytes] | None = None
        try:
            self._proc = subprocess.Popen(
                [
                    sys.executable,
                    "-c",
                    pin + _TRAMPOLINE,
                    str(child_in),
                    str(child_out),
                    exe,
                    *args,
                ],
                stdin=subprocess.DEVNULL,
                stdout=self._stderr,
                stderr=self._stderr,
                pass_fds=(child_in, child_out),
                start_new_session=True,
            )
        finally:
            os.close(child_in)
            os.close(child_out)
        try:
            self._cdp = _Devtools(self._who, to_w, from_r, time.monotonic() + timeout)
            target = self._cdp.call("Target.createTarget", {"url": "about:blank"})["targetId"]
            self._session = self._cdp.call(
                "Target.attachToTarget", {"targetId": target, "flatten": True}
            )["sessionId"]
            self.call(
                "Emulation.setDeviceMetricsOverride",
                {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
            )
            self.call("Page.navigate", {"url": url})
        except BaseException:
            self.close()
            raise

    def call(self, method: str, params: dict[str, Any] | None = None) -> Any:
        """A DevTools command in the page's session."""
        try:
            return self._cdp.call(method, params, self._session)
        except SotpyError as exc:
            raise SotpyError(f"{exc}{_log(self._profile)}") from None

    def evaluate(self, expression: str, awaitPromise: bool = False) -> Any:
        """The value of a JavaScript expression in the page (JSON-able values); a
        JavaScript exception raises SotpyError with its text."""
        reply = self.call(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": awaitPromise},
        )
        if "exceptionDetails" in reply:
            details = reply["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            raise SotpyError(f"HeadlessPage: {expression[:80]!r} raised: {text}")
        return reply.get("result", {}).get("value")

    def waitFor(self, expression: str, timeout: float = 30.0, poll: float = 0.1) -> Any:
        """Wait until ``expression`` is truthy in the page (at most ``timeout`` s);
        returns its value."""
        deadline = time.monotonic() + timeout
        last: Any = None
        while True:
            try:
                last = self.evaluate(expression)
            except SotpyError:
                last = None
            if last:
                return last
            if time.monotonic() > deadline:
                raise SotpyError(
                    f"HeadlessPage: {expression!r} still false after {timeout:g} s (got {last!r})"
                )
            time.sleep(poll)

    def screenshot(self, path: str | os.PathLike[str]) -> str:
        """Save the page as a PNG at ``path``; returns the path."""
        self.evaluate(
            "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(1))))",
            awaitPromise=True,
        )
        data = self.call("Page.captureScreenshot", {"format": "png"})["data"]
        Path(path).write_bytes(base64.b64decode(data))
        return str(path)

    def close(self) -> None:
        """Close Chromium and remove its profile. Idempotent."""
        cdp = getattr(self, "_cdp", None)
        if cdp is not None:
            with contextlib.suppress(SotpyError, OSError):
                cdp._deadline = time.monotonic() + 5.0
                cdp.call("Browser.close")
            self._cdp = None
        for fd in self._fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fds = []
        if self._proc is not None:
            _endSession(self._proc)
            self._proc = None
        with contextlib.suppress(Exception):
            self._stderr.close()
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> HeadlessPage:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
