"""What goes wrong with a live rig's camera streams, said once per cause and shown while it lasts.

A camera falls silent (unplugged, its driver stopped) while the others send; its images cannot be
used (another size than the rig file's, an encoding the detector does not read, truncated data);
its stamps jump (a restarted driver, a clock step, a bag played again: :mod:`timeline`); images go
missing between the camera and the node (gaps in its stamps). :class:`StreamFaults` keeps the
evidence per camera: the node feeds it every arrival and every unusable image, asks it once a
second what is wrong now (the cameras' diagnostics go to WARN with these lines) and logs the lines
it hands back, each once per cause (and again once the cause went away and came back). Nothing
here drops an image: a usable image between unusable ones is used.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from wand_calib_ros.collection.timeline import SAME_JUMP_S, Placed, StampJump, TimeLines

#: A camera without an image for this long (s) while another camera sends is silent.
SILENT_S = 2.0
#: An unusable image is shown as the camera's fault for this long (s) after the last one.
PROBLEM_HOLD_S = 5.0
#: Dropped images are said once this many are missing (diagnostics count every one).
DROPS_SAID = 10


@dataclass(frozen=True)
class Said:
    """A line for the log: ``warning`` or ``info``."""

    level: str
    line: str


class SaidOnce:
    """The causes said so far per camera: each is said once."""

    def __init__(self) -> None:
        self._said: dict[str, set[str]] = {}

    def first(self, camera: str, cause: str) -> bool:
        """Whether ``cause`` is new for ``camera`` (it counts as said from now on)."""
        said = self._said.setdefault(camera, set())
        if cause in said:
            return False
        said.add(cause)
        return True


def image_problem(reason: str, shape: tuple[int, ...] | None, encoding: str, size: tuple[int, int]) -> str | None:
    """What is wrong with an image the detector refused (None: nothing a user must fix).

    Args:
        reason: the detector's reason (``wrong_size``, ``encoding``, ``bad_image``; others are no fault).
        shape: the image's array shape, None when its data could not be read.
        encoding: its encoding.
        size: the camera's (width, height) in the rig file.
    """
    if reason == "wrong_size" and shape is not None and len(shape) >= 2:
        return (
            f"its images are {shape[1]}x{shape[0]}, the rig file says {size[0]}x{size[1]}: check its image_size "
            "and image_topic (a scaled or cropped stream?)"
        )
    if reason == "encoding":
        return (
            f"its images are {encoding}, which the detector does not read (mono8, mono16, bgr8, rgb8, bgra8, "
            "rgba8, bayer_*8): publish one of those"
        )
    if reason == "bad_image":
        return f"an image ({encoding}) could not be read: its data are truncated or corrupt"
    return None


@dataclass
class _Camera:
    arrived_ns: int | None = None
    silent_since_ns: int | None = None  # when it was said silent (its last arrival), until it sends again
    problems: dict[str, tuple[int, str]] = field(default_factory=dict)  # reason -> (last arrival, text)
    drops_said: bool = False


class StreamFaults:
    """The rig's camera streams' faults (see the module docstring)."""

    def __init__(self, cameras: tuple[str, ...], topics: Mapping[str, str]) -> None:
        self.cameras = cameras
        self.topics = dict(topics)
        self.timelines = TimeLines(cameras)  #: each camera's time line (the one place that decides it)
        self._state = {name: _Camera() for name in cameras}
        self._first_ns: int | None = None  # the rig's first arrival
        self._jumps: tuple[int, list[StampJump]] | tuple[()] = ()  # a jump being gathered: (when it began, cameras')

    def arrived(self, camera: str, stamp_ns: int, arrival_ns: int) -> tuple[Placed, list[Said]]:
        """An image (or detector points) of a camera arrived: where it stands on its camera's time line
        (:class:`~wand_calib_ros.collection.timeline.TimeLines`), and what to say about it.

        Args:
            camera: the camera.
            stamp_ns: its header stamp.
            arrival_ns: when it arrived, on a steady clock.
        """
        state = self._state[camera]
        said: list[Said] = []
        if state.silent_since_ns is not None:
            gone = (arrival_ns - state.silent_since_ns) / 1e9
            said.append(Said("info", f"{camera}: images again after {gone:.1f} s without"))
            state.silent_since_ns = None
        placed = self.timelines.place(camera, stamp_ns, arrival_ns)
        jump = placed.jump
        gathered = {j.camera for j in self._jumps[1]} if self._jumps else set()
        # said once whole: when every camera jumped with it, when a camera outside it sends on without jumping (it
        # is those cameras' jump alone), or SAME_JUMP_S after it began
        said += self._said_jumps(arrival_ns, now=jump is None and bool(gathered) and camera not in gathered)
        if jump is not None and jump.kind == "unstamped":  # (the segments say an unstamped camera once)
            said.append(Said("warning", jump.describe()))
        elif jump is not None and jump.shared and self._jumps:  # the same jump as a moment ago: one cause
            self._jumps[1].append(jump)
            if len(self._jumps[1]) == len(self.cameras):  # every camera: said now, once
                said += self._said_jumps(arrival_ns, now=True)
        elif jump is not None:  # said once the cameras that jump with it did (SAME_JUMP_S), or all of them
            said += self._said_jumps(arrival_ns, now=True)
            self._jumps = (arrival_ns, [jump])
            if len(self.cameras) == 1:
                said += self._said_jumps(arrival_ns, now=True)
        state.arrived_ns = arrival_ns
        self._first_ns = arrival_ns if self._first_ns is None else self._first_ns
        return placed, said

    def _said_jumps(self, arrival_ns: int, *, now: bool = False) -> list[Said]:
        """The jump being gathered, said once (as one cause for the cameras that jumped together) when ``now`` or
        SAME_JUMP_S after it began; nothing when none is being gathered."""
        if not self._jumps or (not now and arrival_ns - self._jumps[0] <= SAME_JUMP_S * 1e9):
            return []
        jumps = self._jumps[1]
        self._jumps = ()
        if len(jumps) == 1:
            return [Said("warning", jumps[0].describe())]
        first = jumps[0]
        size = f"{abs(first.jump_s):.1f} s" if abs(first.jump_s) < 3600 else f"{abs(first.jump_s) / 3600:.1f} h"
        who = "every camera's" if len(jumps) == len(self.cameras) else ", ".join(j.camera for j in jumps) + ":"
        return [
            Said(
                "warning",
                f"{who} stamps jumped {size} {'back' if first.kind == 'back' else 'ahead'} together (the host's clock "
                "stepped, or a bag played again?): one shift for all, their frames stay frames; nothing is lost",
            )
        ]

    def unusable(self, camera: str, reason: str, text: str | None, arrival_ns: int) -> list[Said]:
        """An image of a camera the detector could not use, for ``reason`` (``text``: what is wrong, None: no
        fault of the stream); what to say about it."""
        if text is None:
            return []
        state = self._state[camera]
        fresh = reason not in state.problems or arrival_ns - state.problems[reason][0] > PROBLEM_HOLD_S * 1e9
        state.problems[reason] = (arrival_ns, text)
        return [Said("warning", f"{camera}: {text}")] if fresh else []

    def check(self, now_ns: int) -> tuple[dict[str, list[str]], list[Said]]:
        """(per camera its faults now, what to say now): silence, unusable images, dropped images."""
        faults: dict[str, list[str]] = {name: [] for name in self.cameras}
        said: list[Said] = self._said_jumps(now_ns)
        heard = [s.arrived_ns for s in self._state.values() if s.arrived_ns is not None]
        newest = max(heard) if heard else None
        others_send = newest is not None and now_ns - newest <= SILENT_S * 1e9
        for name, state in self._state.items():
            last = state.arrived_ns if state.arrived_ns is not None else self._first_ns  # (never sent: since the rig)
            if others_send and last is not None and now_ns - last > SILENT_S * 1e9:
                line = self._silence(name, state, now_ns)
                faults[name].append(line)
                if state.silent_since_ns is None:
                    state.silent_since_ns = last
                    said.append(Said("warning", f"{name}: {line}"))
            state.problems = {
                reason: (when, text)
                for reason, (when, text) in state.problems.items()
                if now_ns - when <= PROBLEM_HOLD_S * 1e9
            }
            faults[name] += [text for _, text in state.problems.values()]
            dropped = self.timelines.dropped(name)
            if dropped >= DROPS_SAID and not state.drops_said:
                state.drops_said = True
                said.append(
                    Said(
                        "warning",
                        f"{name}: {dropped} images missing in its stamps so far (lost between the camera and this "
                        "node: check the bandwidth, the QoS depth and the CPU load)",
                    )
                )
        return faults, said

    def values(self, camera: str) -> dict[str, int]:
        """Diagnostics counters of a camera's stream (its time line's)."""
        return self.timelines.values(camera)

    def _silence(self, name: str, state: _Camera, now_ns: int) -> str:
        if state.arrived_ns is None:
            topic = self.topics.get(name, "its topic")
            return f"no image on {topic} yet while the other cameras send (check its topic)"
        gone = (now_ns - state.arrived_ns) / 1e9
        return f"no image for {gone:.0f} s while the other cameras send (unplugged? its driver stopped?)"
