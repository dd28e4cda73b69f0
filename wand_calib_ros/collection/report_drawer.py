"""A calibration's report drawn after its answer: the result files are written and said at once, the
report (matplotlib figures, about a second) follows in a thread of its own.

One report is drawn at a time. A calibration that ends while an earlier one's report is drawn waits
for it to finish, then its own is drawn; a report still waiting when a newer one comes is dropped,
since the newer one will be written to the same folder. Each report is drawn from the result as it
was written (:attr:`ReportRequest.document`), so a calibration that replaces ``result.yaml``
meanwhile cannot mix into an earlier report.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.errors import WandCalibError

log = logging.getLogger(__name__)

#: The report's page in its folder.
REPORT_PAGE = "index.html"


@dataclass(frozen=True, eq=False)
class ReportRequest:
    """One calibration's report, to be drawn.

    Attributes:
        rig: the rig calibrated.
        observations: the views the calibration used (or, for a repair, the views after the move).
        result_path: the calibration's ``result.yaml``.
        document: the result as written there (:func:`~wand_calib_ros.io.result_yaml.result_to_dict`).
        folder: where the report goes (``output_dir/report``).
        observations_path: the buffer file the views came from (the detector's account beside it is shown).
        source: what asked for it, for the log (``/calibrate``, ``/refine``, ``auto_calibrate``).
    """

    rig: RigSpec
    observations: WandObservations
    result_path: Path
    document: dict[str, Any]
    folder: Path
    observations_path: Path | None
    source: str

    @property
    def page(self) -> Path:
        """Where the report's page will be."""
        return self.folder / REPORT_PAGE


@dataclass(frozen=True)
class DrawnReport:
    """What drawing a report came to.

    Attributes:
        request: the report asked for.
        seconds: how long it took to draw and write.
        error: why it failed (None: ``request.page`` is written).
    """

    request: ReportRequest
    seconds: float
    error: str | None = None

    def line(self) -> str:
        """One line for the log: where the report is, or why there is none."""
        if self.error is not None:
            return f"{self.request.source}: the calibration is written, but its report failed: {self.error}"
        return f"{self.request.source}: report ready in {self.request.page} ({self.seconds:.1f} s)"


def load_report_drawing() -> None:
    """Import what drawing a report needs (matplotlib: 0.4 s and 55 MB measured), so that the first report
    does not wait for it."""
    import wand_calib_ros.report.html  # noqa: F401


def draw_report(request: ReportRequest) -> None:
    """Draw and write one report (matplotlib is imported here, unless :func:`load_report_drawing` did).

    Raises:
        WandCalibError, OSError, ValueError, numpy.linalg.LinAlgError: the report could not be drawn or written.
    """
    from wand_calib_ros.report.html import write_report

    write_report(
        request.rig,
        request.observations,
        request.result_path,
        request.folder,
        request.observations_path,
        request.document,
    )


class ReportDrawer:
    """Draws the reports it is given, newest last, in one daemon thread of its own (module docstring)."""

    def __init__(
        self,
        said: Callable[[DrawnReport], None],
        draw: Callable[[ReportRequest], None] = draw_report,
        load: Callable[[], None] = load_report_drawing,
    ) -> None:
        """Start the drawing thread, which first loads what drawing needs (``load``).

        Args:
            said: called from the drawing thread with each report drawn (or failed).
            draw: draws one report (tests give a slow or failing one).
            load: imports what ``draw`` needs, before the first report is asked for.
        """
        self._said = said
        self._draw = draw
        self._changed = threading.Condition()
        self._waiting: ReportRequest | None = None
        self._drawing = False
        self._loading = True
        self._thread = threading.Thread(target=self._run, args=(load,), name="report", daemon=True)
        self._thread.start()

    def submit(self, request: ReportRequest) -> Path:
        """Draw ``request`` after the report being drawn (replacing one still waiting); returns its page."""
        with self._changed:
            if self._waiting is not None:
                log.info("%s: its report is not drawn; a newer calibration's follows", self._waiting.source)
            self._waiting = request
            self._changed.notify_all()
        return request.page

    @property
    def busy(self) -> bool:
        """Whether a report is being drawn or waits to be."""
        with self._changed:
            return self._drawing or self._waiting is not None

    @property
    def active(self) -> bool:
        """Whether the drawing thread is doing anything (loading, drawing; a process must not end normally
        under it: its interpreter's finalisation would stop it inside matplotlib's C code)."""
        with self._changed:
            return self._loading or self._drawing or self._waiting is not None

    def wait(self, timeout_s: float) -> bool:
        """Wait until no report is drawn or waiting (at most ``timeout_s``); True when none is."""
        with self._changed:
            return self._changed.wait_for(lambda: not (self._drawing or self._waiting is not None), timeout_s)

    def _run(self, load: Callable[[], None]) -> None:
        try:
            load()
        except Exception:  # (said again, and plainly, by the first report that needs it)
            log.exception("loading what drawing a report needs")
        with self._changed:
            self._loading = False
        while True:
            with self._changed:
                self._changed.wait_for(lambda: self._waiting is not None)
                request, self._waiting, self._drawing = self._waiting, None, True
            assert request is not None
            began = time.perf_counter()
            try:
                self._draw(request)
                drawn = DrawnReport(request, time.perf_counter() - began)
            except (OSError, ValueError, np.linalg.LinAlgError, WandCalibError) as error:
                drawn = DrawnReport(request, time.perf_counter() - began, str(error))
            except Exception as error:  # a bug: said, and the next report is still drawn
                log.exception("drawing the report of %s", request.source)
                why = f"unexpected error (please report): {error!r}"
                drawn = DrawnReport(request, time.perf_counter() - began, why)
            try:
                self._said(drawn)
            except Exception:  # (a bug in the caller's callback must not stop the reports that follow)
                log.exception("saying the report of %s", request.source)
            with self._changed:
                self._drawing = False
                self._changed.notify_all()
