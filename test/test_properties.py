"""Property tests: random bytes, documents and images at the parsers and the detector, spoilt inputs at
the commands.

Whatever comes in, the answer is a valid result or a typed error (FormatError, ImageError, ...),
never another exception. Seeded (``derandomize``) so CI sees the same cases every run.
"""

from __future__ import annotations

import contextlib
import io
import string
import tempfile
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wand_calib_ros.cli import main
from wand_calib_ros.collection.buffer import ObservationBuffer
from wand_calib_ros.core.initialise.intrinsics_init import nominal_bearings
from wand_calib_ros.detection.blobs import BlobOptions
from wand_calib_ros.detection.errors import DetectionError
from wand_calib_ros.detection.recording import detect_image
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.io.rig_yaml import load_rig
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

RIG = paper_fisheye_scenario().rig
SETTINGS = settings(
    max_examples=300, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

cells = st.one_of(
    st.integers(-3, 300).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["cam0", "cam1", "cam9", "A", "B", "C", "D", "", " ", "nan", "1e400", "0x10", '"', "\x00"]),
    st.text(string.printable, max_size=6),
)
headers = st.one_of(
    st.just("frame,camera,point,u,v"),
    st.just("frame,camera,point,u,v,stamp"),
    st.lists(st.sampled_from(["frame", "camera", "point", "u", "v", "stamp", "x", ""]), max_size=7).map(",".join),
)
csv_documents = st.tuples(headers, st.lists(st.lists(cells, max_size=8).map(",".join), max_size=12)).map(
    lambda parts: "\n".join([parts[0], *parts[1]]) + "\n"
)
yaml_values: st.SearchStrategy[Any] = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-5, 2000), st.floats(allow_nan=True), st.text(max_size=6)),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(
            st.sampled_from(["wand", "L1", "L2", "cameras", "name", "image_size", "pixel_size_um", "k", "m"]), inner
        ),
    ),
    max_leaves=12,
)


def _good_rig_document() -> dict[str, Any]:
    return yaml.safe_load((Path(__file__).parent / "data" / "ewand" / "cameras.yaml").read_text())


def _read_csv(path: Path) -> None:
    try:
        observations = read_observations(path, RIG.camera_names, image_sizes=RIG.image_sizes)
    except WandCalibError:
        return
    assert observations.uv.shape[1:] == (2, 3, 2)


@SETTINGS
@given(content=st.binary(max_size=300))
def test_random_bytes_as_any_input_file(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "input"
    path.write_bytes(content)
    _read_csv(path)
    for reader in (load_rig, read_result):
        with contextlib.suppress(WandCalibError):
            reader(path)


@SETTINGS
@given(text=csv_documents)
def test_random_csv_documents(tmp_path: Path, text: str) -> None:
    path = tmp_path / "observations.csv"
    path.write_text(text, encoding="utf-8")
    _read_csv(path)


@SETTINGS
@given(document=yaml_values)
def test_random_yaml_documents_as_cameras_yaml(tmp_path: Path, document: Any) -> None:
    path = tmp_path / "cameras.yaml"
    path.write_text(yaml.safe_dump(document))
    with contextlib.suppress(WandCalibError):
        load_rig(path)


@SETTINGS
@given(key=st.sampled_from(["wand", "cameras"]), value=yaml_values, camera_key=st.text(max_size=12), item=yaml_values)
def test_a_real_rig_document_with_one_part_replaced(
    tmp_path: Path, key: str, value: Any, camera_key: str, item: Any
) -> None:
    document = _good_rig_document()
    document[key] = value
    if isinstance(document.get("cameras"), list) and document["cameras"]:
        first = document["cameras"][0]
        if isinstance(first, dict):
            first[camera_key or "name"] = item
    path = tmp_path / "cameras.yaml"
    path.write_text(yaml.safe_dump(document))
    with contextlib.suppress(WandCalibError):
        load_rig(path)


@SETTINGS
@given(content=st.binary(max_size=400), tail=st.binary(max_size=40))
def test_random_buffer_files_resume_or_are_refused(content: bytes, tail: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:  # one per example: a repair leaves a copy behind
        path = Path(folder) / "observations.csv"
        path.write_bytes(b"frame,camera,point,u,v,stamp\n" + content + tail)
        before = path.read_bytes()
        try:
            buffer = ObservationBuffer.open(path, RIG)
        except WandCalibError:
            assert path.read_bytes() == before and list(path.parent.iterdir()) == [path]  # refused: nothing changed
            return
        assert buffer.next_frame >= 0


MODEL = nominal_bearings(RIG.cameras[0])
ENCODINGS = ["mono8", "mono16", "bgr8", "rgb8", "bayer_rggb8", "rgba8", "32FC1", "jpeg", ""]


@SETTINGS
@given(
    shape=st.tuples(st.integers(0, 40), st.integers(0, 40), st.sampled_from([0, 1, 2, 3, 4])),
    encoding=st.sampled_from(ENCODINGS),
    dtype=st.sampled_from([np.uint8, np.uint16, np.float32, np.int8]),
    seed=st.integers(0, 2**16),
    spots=st.integers(0, 6),
)
def test_random_images_give_a_detection_or_an_image_error(
    shape: tuple[int, int, int], encoding: str, dtype: type, seed: int, spots: int
) -> None:
    rng = np.random.default_rng(seed)
    size = shape[:2] if shape[2] == 0 else shape
    image = rng.integers(0, 40, size=size).astype(dtype)
    if image.ndim >= 2 and image.shape[0] and image.shape[1]:
        for _ in range(spots):
            image[rng.integers(0, image.shape[0]), rng.integers(0, image.shape[1])] = 120
    try:
        blobs, detection = detect_image(image, encoding, BlobOptions(), WandOptions(), MODEL)
    except DetectionError:
        return
    assert blobs.centres.shape[1:] == (2,)
    assert (detection.points is None) == (detection.reason is not None)


@cache
def _good_run() -> Path:
    """A good run's files, made once: a simulated rig, its observations, its result and a point file."""
    folder = Path(tempfile.mkdtemp(prefix="wand-calib-good-"))
    assert main(["-q", "simulate", "paper", "--seed", "3", "--noise", "0.5", "--out", str(folder)]) == 0
    files = ["--cameras", str(folder / "cameras.yaml"), "--observations", str(folder / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(folder / "result.yaml")]) == 0
    observations = read_observations(folder / "observations.csv", RIG.camera_names)
    header = [f"pt{p + 1}_cam{c + 1}_{a}" for p in range(3) for c in range(2) for a in "xy"]
    rows = [",".join(f"{v:.3f}" for p in range(3) for c in range(2) for v in (u[c, p, 0], 480 - u[c, p, 1]))
            for u in observations.uv]  # fmt: skip
    (folder / "points.csv").write_text("\n".join([",".join(header), *rows]) + "\n")
    return folder


#: The commands whose error paths the property test drives: (name, the input files it may spoil, argv).
COMMANDS = {
    "calibrate": (("cameras.yaml", "observations.csv"), "calibrate --cameras {cameras} --observations "
                  "{observations} --output {out}/result.yaml --floor 0-9"),
    "export": (("result.yaml",), "export --result {result} --format opencv --out {out}/export"),
    "refine": (("cameras.yaml", "result.yaml", "observations.csv"), "refine --cameras {cameras} --result "
               "{result} --observations {observations} --output {out}/refined.yaml --moved cam1"),
    "import": (("cameras.yaml", "points.csv"), "import --format xypts --points {points} --cameras "
               "{cameras} --out {out}/observations.csv"),
}  # fmt: skip


def _spoilt(text: str, mutation: tuple[str, float, str]) -> str:
    """``text`` with one mutation: cut at a fraction of it, a span replaced, or one YAML scalar replaced."""
    kind, where, insert = mutation
    at = int(where * len(text))
    if kind == "cut":
        return text[:at]
    if kind == "replace":
        return text[:at] + insert + text[at + len(insert) :]
    lines = text.splitlines()  # a line's value after its first ': ' or ','
    line = int(where * (len(lines) - 1))
    separator = ": " if ": " in lines[line] else ","
    head, found, _ = lines[line].partition(separator)
    lines[line] = head + (found or separator) + insert
    return "\n".join(lines) + "\n"


mutations = st.tuples(
    st.sampled_from(["cut", "replace", "value"]),
    st.floats(0.0, 1.0),
    st.one_of(st.text(string.printable, max_size=8), st.sampled_from(["nan", "-1", "0", "[]", "{}", "1e300", ".inf"])),
)


@settings(max_examples=80, derandomize=True, deadline=None)
@given(command=st.sampled_from(sorted(COMMANDS)), which=st.integers(0, 2), mutation=mutations)
def test_every_command_answers_a_spoilt_input_with_one_line_and_writes_nothing(
    command: str, which: int, mutation: tuple[str, float, str]
) -> None:
    good = _good_run()
    spoilable, template = COMMANDS[command]
    name = spoilable[which % len(spoilable)]
    with tempfile.TemporaryDirectory() as work:
        folder = Path(work)
        files = ("cameras.yaml", "observations.csv", "result.yaml", "points.csv")
        paths = {f.split(".")[0]: str(good / f) for f in files}
        (folder / name).write_text(_spoilt((good / name).read_text(), mutation), encoding="utf-8")
        paths[name.split(".")[0]] = str(folder / name)
        argv = template.format(**paths, out=folder / "out").split()
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr):
            code = main(["-q", *argv])
        err = stderr.getvalue()
        assert code in (0, 2) and "Traceback" not in err, err
        if code == 2:
            errors = [line for line in err.splitlines() if line.startswith("wand-calib: error: ")]
            assert len(errors) == 1 and all(line.startswith("wand-calib: ") for line in err.splitlines()), err
            written = [p for p in (folder / "out").rglob("*") if p.is_file()] if (folder / "out").exists() else []
            assert not written, written
