"""What the detector saw, kept beside the observations it wrote: ``<stem>.detection.yaml`` and its masks.

``wand-calib detect --output obs.csv`` and the live collector (``observations.csv`` in its output
folder) write, next to the observations, ``obs.detection.yaml``:

```yaml
cameras:
  cam0:
    images: 1800            # images received
    views: 1402             # views of the wand labelled
    no_view: {too_few_blobs: 250, ambiguous: 12, still: 40}    # images without a view, by reason
    static_lights: [[412.3, 115.0, 11.2]]                     # (u, v, radius px) learned and masked
    masked_fraction: 0.0021                                    # of the image ignored
    mask: obs.masks/cam0.png                                   # the mask the detector ended with
    saturated: 0.62         # fraction of the views' LEDs that reach the image's maximum value
    dim: 0.04               # fraction of the views whose dimmest LED is within 2x of what can be found
    peak_median: 244.0      # grey levels above the background
    streak_median_px: 2.1
    streak_p95_px: 7.9
    messages: ["cam0: its LEDs saturate in 62 % of its views ...: shorten the exposure or dim the LEDs"]
```

and ``obs.masks/<camera>.png`` (white where ignored). The report shows them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.outputs import write_together
from wand_calib_ros.io.result_yaml import yaml_text
from wand_calib_ros.io.text import read_yaml

#: Why an image gave no view, in plain words (the detector's reasons).
REASON_TEXT = {
    "no_blobs": "nothing bright",
    "too_few_blobs": "fewer spots than the wand has LEDs",
    "not_collinear": "no spots in a line like the wand's",
    "competing_triples": "two wand-like lines (ambiguous)",
    "at_border": "an LED cut by the image border or a mask",
    "ambiguous": "A and C could not be told apart",
    "still": "still lights, not a moving wand",
    "wrong_size": "an image of another size than the rig file's",
    "bad_image": "an image that could not be read",
    "encoding": "an image encoding the detector does not read",
    "taking_mask": "taking the mask",
    "late": "stamped before an image of its camera already used (out of order)",
    "repeated_stamp": "its camera's previous stamp again",
    "no_wand": "no wand",
}


def summary_path(observations: Path) -> Path:
    """``<stem>.detection.yaml`` beside an observations CSV."""
    return observations.with_name(f"{observations.stem}.detection.yaml")


def masks_folder(observations: Path) -> Path:
    """``<stem>.masks/`` beside an observations CSV."""
    return observations.with_name(f"{observations.stem}.masks")


def write_summary(observations: Path, cameras: dict[str, dict[str, Any]]) -> Path:
    """Write the detection summary of the observations at ``observations``; returns its path."""
    path = summary_path(observations)
    write_together({path: yaml_text({"cameras": cameras})})
    return path


def read_summary(observations: Path) -> dict[str, dict[str, Any]] | None:
    """The detection summary beside ``observations`` (None: there is none).

    Raises:
        FormatError: it is not one.
    """
    path = summary_path(observations)
    if not path.is_file():
        return None
    document = read_yaml(path)
    cameras = document.get("cameras") if isinstance(document, dict) else None
    if not isinstance(cameras, dict) or not all(isinstance(v, dict) for v in cameras.values()):
        raise FormatError(path, "not a detection summary: expected cameras: {<camera>: {images: ..., views: ...}}")
    return {str(name): dict(values) for name, values in cameras.items()}
