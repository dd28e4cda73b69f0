"""Root of the typed errors raised by wand_calib_ros.

Every error a user can cause (bad files, too little data, a model that cannot
describe the lens) derives from :class:`WandCalibError`; the CLI and the ROS
nodes turn it into one clear line. Anything else is a bug.
"""

from __future__ import annotations


class WandCalibError(Exception):
    """Base class for errors a user can act on."""
