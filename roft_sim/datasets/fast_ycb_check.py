"""An independent checker of Fast-YCB sequence folders.

Written apart from the reader (:mod:`roft_sim.datasets.fast_ycb`) on purpose: it parses headers
with :mod:`struct`, PNG headers by hand, rotations with OpenCV's ``Rodrigues`` and scipy, and
shares no code with the writer or the reader, so a bug in those does not hide itself here.

What it checks (each finding is one line naming the file, and line or frame, and the problem):

- ``cam_K.json``: keys, numbers (strings allowed), fx/fy/cx/cy on lines 5-8 as ROFT's scripts
  read them.
- ``data.txt``: one row of 9 numbers per frame, increasing time, camera axis-angle rows.
- ``rgb/``, ``depth/``, ``optical_flow/<set>/``, ``masks/<set>/``: file names and counts (flow:
  1..N-1, no file 0), PNG signatures and sizes, binary headers, exact byte sizes, finite values.
- ``<set>/poses.txt`` and ``gt/poses.txt``: seven numbers per row, unit axis, angle in
  [0, pi] (detector rows may be seven zeros, ground truth not).
- ``gt/velocities.txt``: rows of six numbers, consistent with ``gt/poses.txt`` by central finite
  differences (relative RMS residual <= ``VELOCITY_RELATIVE_TOLERANCE``).
- Flow direction: on frames with ground truth, file k must map frame k-1 to k: the stored flow at
  the object's pixels of frame k-1 must agree with the motion field computed from the depth of
  frame k-1 and the poses of frames k-1 and k better than the reversed flow would.
- ``metadata.json`` (ours): valid JSON stating the frame count and the velocity convention;
  ``models/<object>/points.xyz``.
"""

from __future__ import annotations

import json
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from roft_sim.errors import ConfigError

__all__ = [
    "check_fast_ycb_sequence",
    "run_fast_ycb_check",
    "FastYcbCheckReport",
    "VELOCITY_RELATIVE_TOLERANCE",
    "AXIS_UNIT_TOLERANCE",
]

VELOCITY_RELATIVE_TOLERANCE = 0.2
"""Largest accepted ``rms(v_fd - v) / max(rms(v), floor)`` (floors 0.01 m/s, 0.05 rad/s)."""
AXIS_UNIT_TOLERANCE = 1e-5
"""Largest accepted | |axis| - 1 | in axis-angle rows."""
FLOW_MIN_MOTION_PX = 2.0
"""Frames whose median expected motion is below this are not used for the direction check."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_COLOUR = {0: "grey", 2: "RGB", 3: "palette", 4: "grey+alpha", 6: "RGBA"}


@dataclass
class FastYcbCheckReport:
    """Result of :func:`run_fast_ycb_check`."""

    path: Path
    problems: list[str] = field(default_factory=list)
    """One line per defect found; empty = the folder passed."""
    notes: list[str] = field(default_factory=list)
    """Checks skipped (with the reason) and measured agreement numbers."""

    @property
    def ok(self) -> bool:
        return not self.problems


def check_fast_ycb_sequence(path: str | Path) -> list[str]:
    """Problems found in a Fast-YCB sequence folder (empty list = it passed)."""
    return run_fast_ycb_check(path).problems


def run_fast_ycb_check(path: str | Path, *, max_flow_frames: int = 20) -> FastYcbCheckReport:
    """Checks a Fast-YCB sequence folder; see the module doc for what is checked.

    Args:
        path: the sequence folder.
        max_flow_frames: frames (evenly spread) used per flow set for the direction check, >= 1.

    Raises:
        ConfigError: ``max_flow_frames`` below 1 (it would skip the flow check silently).
    """
    if max_flow_frames < 1:
        raise ConfigError(f"max_flow_frames must be >= 1, got {max_flow_frames}")
    return _Checker(Path(path), max_flow_frames).run()


def _read_rows(path: Path, n_cols: int, problems: list[str]) -> np.ndarray | None:
    """Rows of ``n_cols`` numbers; reports malformed lines and returns None on any."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        problems.append(f"{path}: cannot read: {e}")
        return None
    while lines and not lines[-1].strip():
        lines.pop()
    rows = []
    ok = True
    for i, line in enumerate(lines, start=1):
        parts = line.split()
        if len(parts) != n_cols:
            problems.append(f"{path}, line {i}: {len(parts)} numbers, expected {n_cols}")
            ok = False
            continue
        try:
            values = [float(p) for p in parts]
        except ValueError:
            problems.append(f"{path}, line {i}: not all numbers: {line.strip()[:60]!r}")
            ok = False
            continue
        if not all(np.isfinite(values)):
            problems.append(f"{path}, line {i}: NaN or inf")
            ok = False
            continue
        rows.append(values)
    return np.array(rows, dtype=np.float64).reshape(-1, n_cols) if ok else None


def _rotation_from_axis_angle(axis_angle: np.ndarray) -> np.ndarray:
    """3x3 rotation via OpenCV's Rodrigues (independent of roft_sim.geometry)."""
    axis, angle = axis_angle[:3], axis_angle[3]
    n = np.linalg.norm(axis)
    rvec = axis / n * angle if n > 0 else np.zeros(3)
    R, _ = cv2.Rodrigues(rvec.reshape(3, 1))
    return R


def _png_header(data: bytes) -> tuple[int, int, int, int] | None:
    """(width, height, bit depth, colour type) from a PNG's IHDR, or None if not a PNG."""
    if len(data) < 33 or data[:8] != _PNG_SIGNATURE or data[12:16] != b"IHDR":
        return None
    width, height, depth, colour = struct.unpack(">IIBB", data[16:26])
    return width, height, depth, colour


class _Checker:
    def __init__(self, path: Path, max_flow_frames: int) -> None:
        self.path = path
        self.report = FastYcbCheckReport(path=path)
        self.max_flow_frames = max_flow_frames
        self.width = self.height = 0
        self.K = np.eye(3)
        self.n = 0
        self.times = np.zeros(0)
        self.object_name: str | None = None
        self.gt_poses: list[np.ndarray] | None = None
        self._depth_cache: dict[int, np.ndarray] = {}
        self._flow_sample: set[int] = set()
        self._depth_needed: set[int] = set()

    def problem(self, text: str) -> None:
        self.report.problems.append(text)

    def note(self, text: str) -> None:
        self.report.notes.append(text)

    def run(self) -> FastYcbCheckReport:
        if not self.path.is_dir():
            self.problem(f"{self.path}: not a folder")
            return self.report
        if not self._check_cam_k() or not self._check_data_txt():
            return self.report
        n_sample = min(self.max_flow_frames, self.n - 1)
        if n_sample > 0:
            self._flow_sample = set(np.linspace(1, self.n - 1, n_sample).astype(int).tolist())
        self._depth_needed = {j for i in self._flow_sample for j in (i - 1, i)}
        self._check_metadata()
        self._check_rgb()
        self._check_depth()
        self._check_masks()
        self._check_pose_files()
        self._check_velocities()
        self._check_flows()
        self._check_models()
        return self.report

    # ------------------------------------------------------------------ cam_K, data.txt
    def _check_cam_k(self) -> bool:
        path = self.path / "cam_K.json"
        try:
            text = path.read_text(encoding="utf-8")
            data = json.loads(text)
        except FileNotFoundError:
            self.problem(f"{path}: missing")
            return False
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            self.problem(f"{path}: not valid JSON: {e}")
            return False
        if not isinstance(data, dict):
            self.problem(f"{path}: not a JSON object")
            return False
        values = {}
        for key in ("width", "height", "fx", "fy", "cx", "cy"):
            try:
                values[key] = float(data[key])
            except KeyError:
                self.problem(f"{path}: key {key!r} missing")
            except (TypeError, ValueError):
                self.problem(f"{path}: {key} = {data[key]!r} is not a number")
        if len(values) < 6:
            return False
        for key in ("width", "height"):
            if not values[key].is_integer() or values[key] <= 0:
                self.problem(f"{path}: {key} = {values[key]} is not a positive integer")
                return False
        if values["fx"] <= 0 or values["fy"] <= 0:
            self.problem(f"{path}: focal lengths must be positive")
        lines = text.splitlines()
        for line_no, key in zip(range(5, 9), ("fx", "fy", "cx", "cy"), strict=True):
            if len(lines) < line_no or f'"{key}"' not in lines[line_no - 1]:
                self.problem(
                    f"{path}, line {line_no}: expected the {key!r} entry there (ROFT's scripts "
                    "read fx, fy, cx, cy from lines 5-8)"
                )
        self.width, self.height = int(values["width"]), int(values["height"])
        self.K = np.array(
            [[values["fx"], 0, values["cx"]], [0, values["fy"], values["cy"]], [0, 0, 1.0]]
        )
        return True

    def _check_axis_angle_rows(
        self, path: Path, rows: np.ndarray, col: int, *, zero_ok: bool, first_line: int = 1
    ) -> None:
        for i, row in enumerate(rows):
            pose = row[col : col + 7]
            if not pose.any():
                if not zero_ok:
                    self.problem(f"{path}, line {i + first_line}: a row of zeros (no pose)")
                continue
            axis, angle = pose[3:6], pose[6]
            norm = float(np.linalg.norm(axis))
            if norm == 0.0 and angle == 0.0 and zero_ok:
                continue
            if abs(norm - 1.0) > AXIS_UNIT_TOLERANCE:
                self.problem(
                    f"{path}, line {i + first_line}: axis norm {norm:.9g} is not 1 (axis-angle "
                    "needs a unit axis, angle last)"
                )
            if not -1e-12 <= angle <= np.pi + 1e-12:
                self.problem(f"{path}, line {i + first_line}: angle {angle} is outside [0, pi]")

    def _check_data_txt(self) -> bool:
        path = self.path / "data.txt"
        if not path.is_file():
            self.problem(f"{path}: missing")
            return False
        rows = _read_rows(path, 9, self.report.problems)
        if rows is None:
            return False
        if len(rows) == 0:
            self.problem(f"{path}: no rows")
            return False
        self.n = len(rows)
        self.times = rows[:, 0]
        steps = np.diff(self.times)
        if (steps <= 0).any():
            i = int(np.argmax(steps <= 0)) + 2
            self.problem(f"{path}, line {i}: time stamp does not increase")
        # Camera poses: an all-zero row (ROFT's capture tool) means identity.
        self._check_axis_angle_rows(path, rows, 2, zero_ok=True)
        return True

    def _check_metadata(self) -> None:
        path = self.path / "metadata.json"
        if not path.is_file():
            self.note("metadata.json absent (a dataset not written by roft_sim)")
            return
        try:
            meta = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            self.problem(f"{path}: not valid JSON: {e}")
            return
        if not isinstance(meta, dict):
            self.problem(f"{path}: not a JSON object")
            return
        if meta.get("n_frames") != self.n:
            self.problem(
                f"{path}: n_frames = {meta.get('n_frames')!r} but data.txt has {self.n} rows"
            )
        if "velocity" not in meta.get("conventions", {}):
            self.problem(f"{path}: conventions.velocity (the velocity convention) is not stated")
        if isinstance(meta.get("object_name"), str):
            self.object_name = meta["object_name"]

    # ----------------------------------------------------------------------- image files
    def _listing(self, folder: Path) -> list[str] | None:
        try:
            return [n for n in os.listdir(folder) if not n.startswith(".")]
        except FileNotFoundError:
            self.problem(f"{folder}: folder missing")
            return None

    def _expect_indexed_files(
        self, folder: Path, pattern: str, indices: range, *, required: bool = True
    ) -> dict[int, Path]:
        """Files ``pattern`` (regex with one (\\d+) group) in ``folder``; reports strays."""
        names = self._listing(folder)
        if names is None:
            return {}
        rx = re.compile(pattern)
        found: dict[int, Path] = {}
        for name in sorted(names):
            m = rx.fullmatch(name)
            if not m or (m.group(1) != "0" and m.group(1).startswith("0")):
                self.problem(f"{folder / name}: unexpected file (expected {pattern}, no padding)")
                continue
            i = int(m.group(1))
            if i not in indices:
                self.problem(
                    f"{folder / name}: index {i} outside {indices.start}..{indices.stop - 1}"
                )
                continue
            found[i] = folder / name
        if required:
            missing = sorted(set(indices) - set(found))
            if missing:
                shown = ", ".join(map(str, missing[:10])) + (" ..." if len(missing) > 10 else "")
                self.problem(f"{folder}: {len(missing)} files missing (indices {shown})")
        return found

    def _check_png(self, path: Path, colours: set[int], what: str) -> bytes | None:
        try:
            data = path.read_bytes()
        except OSError as e:
            self.problem(f"{path}: cannot read: {e}")
            return None
        header = _png_header(data)
        if header is None:
            self.problem(f"{path}: not a PNG file")
            return None
        w, h, depth, colour = header
        if (w, h) != (self.width, self.height):
            self.problem(f"{path}: {w}x{h} px, cam_K.json says {self.width}x{self.height}")
        if depth != 8 or colour not in colours:
            self.problem(
                f"{path}: {depth}-bit {_PNG_COLOUR.get(colour, colour)}; {what} must be 8-bit "
                + " or ".join(_PNG_COLOUR[c] for c in sorted(colours))
            )
        return data

    def _check_rgb(self) -> None:
        files = self._expect_indexed_files(self.path / "rgb", r"(\d+)\.png", range(self.n))
        for path in files.values():
            self._check_png(path, {2, 6}, "rgb images")

    def _read_depth(self, path: Path) -> np.ndarray | None:
        try:
            data = path.read_bytes()
        except OSError as e:
            self.problem(f"{path}: cannot read: {e}")
            return None
        if len(data) < 16:
            self.problem(f"{path}: {len(data)} bytes, shorter than the 16-byte header")
            return None
        w, h = struct.unpack("<QQ", data[:16])
        if (w, h) != (self.width, self.height):
            self.problem(f"{path}: header says {w}x{h}, cam_K.json {self.width}x{self.height}")
            return None
        if len(data) != 16 + 4 * w * h:
            self.problem(f"{path}: {len(data)} bytes, expected 16 + 4*{w}*{h} = {16 + 4 * w * h}")
            return None
        depth = np.frombuffer(data, "<f4", offset=16).reshape(h, w)
        if not np.isfinite(depth).all():
            self.problem(f"{path}: NaN/inf depth values")
            return None
        return depth

    def _check_depth(self) -> None:
        files = self._expect_indexed_files(self.path / "depth", r"(\d+)\.float", range(self.n))
        for i, path in files.items():
            depth = self._read_depth(path)
            if depth is not None and i in self._depth_needed:  # for the flow-direction check
                self._depth_cache[i] = depth

    def _check_masks(self) -> None:
        masks = self.path / "masks"
        if not masks.is_dir():
            self.note("masks/ absent")
            return
        sets = sorted(p.name for p in masks.iterdir() if p.is_dir())
        if self.object_name is None:
            for s in sets:
                for name in sorted(os.listdir(masks / s)):
                    m = re.fullmatch(r"(.+)_\d+\.png", name)
                    if m:
                        self.object_name = m.group(1)
                        break
                if self.object_name:
                    break
        if self.object_name is None:
            self.note("masks/ holds no mask files")
            return
        prefix = re.escape(self.object_name)
        for s in sets:
            files = self._expect_indexed_files(
                masks / s, prefix + r"_(\d+)\.png", range(self.n), required=s in ("gt", "gt_full")
            )
            for path in files.values():
                data = self._check_png(path, {0}, "masks")
                if data is not None and s in ("gt", "gt_full"):
                    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
                    if image is None:
                        self.problem(f"{path}: corrupt PNG")
                    elif not np.isin(image, (0, 255)).all():
                        self.problem(f"{path}: values other than 0 and 255")

    # ---------------------------------------------------------------------- pose files
    def _check_pose_files(self) -> None:
        skip = {"gt", "rgb", "depth", "masks", "optical_flow", "optical_flow_valid", "models"}
        for d in sorted(p for p in self.path.iterdir() if p.is_dir() and p.name not in skip):
            for path in sorted(d.glob("poses*.txt")):
                rows = _read_rows(path, 7, self.report.problems)
                if rows is None:
                    continue
                if len(rows) != self.n:
                    self.problem(f"{path}: {len(rows)} rows, data.txt has {self.n} frames")
                self._check_axis_angle_rows(path, rows, 0, zero_ok=True)
        gt = self.path / "gt" / "poses.txt"
        if not gt.is_file():
            self.note("gt/poses.txt absent (no ground truth): velocity and flow checks skipped")
            return
        rows = _read_rows(gt, 7, self.report.problems)
        if rows is None:
            return
        if len(rows) != self.n:
            self.problem(f"{gt}: {len(rows)} rows, data.txt has {self.n} frames")
            return
        self._check_axis_angle_rows(gt, rows, 0, zero_ok=False)
        poses = []
        for row in rows:
            T = np.eye(4)
            T[:3, :3] = _rotation_from_axis_angle(row[3:7])
            T[:3, 3] = row[:3]
            poses.append(T)
        self.gt_poses = poses
        for path in sorted((self.path / "gt").glob("poses_*.txt")):
            variant = _read_rows(path, 7, self.report.problems)
            if variant is not None:
                if len(variant) != self.n:
                    self.problem(f"{path}: {len(variant)} rows, data.txt has {self.n} frames")
                self._check_axis_angle_rows(path, variant, 0, zero_ok=False)

    def _check_velocities(self) -> None:
        path = self.path / "gt" / "velocities.txt"
        if not path.is_file():
            if self.gt_poses is not None:
                self.note("gt/velocities.txt absent")
            return
        rows = _read_rows(path, 6, self.report.problems)
        if rows is None or self.gt_poses is None:
            return
        if len(rows) != self.n:
            self.problem(f"{path}: {len(rows)} rows, data.txt has {self.n} frames")
            return
        if self.n < 3:
            self.note("velocity consistency not checked: fewer than 3 frames")
            return
        T = np.stack(self.gt_poses)
        t = self.times
        dt = (t[2:] - t[:-2])[:, None]
        v_fd = (T[2:, :3, 3] - T[:-2, :3, 3]) / dt
        R_rel = T[2:, :3, :3] @ np.swapaxes(T[:-2, :3, :3], 1, 2)
        # imported here: scipy.spatial takes half a second, and every command that imports
        # roft_sim.datasets would pay it
        from scipy.spatial.transform import Rotation

        w_fd = Rotation.from_matrix(R_rel).as_rotvec() / dt
        for name, fd, stored, floor, unit in (
            ("linear", v_fd, rows[1:-1, :3], 0.01, "m/s"),
            ("angular", w_fd, rows[1:-1, 3:], 0.05, "rad/s"),
        ):
            residual = np.linalg.norm(fd - stored, axis=1)
            scale = max(float(np.sqrt(np.mean(np.sum(stored**2, axis=1)))), floor)
            rel = float(np.sqrt(np.mean(residual**2))) / scale
            worst = int(np.argmax(residual)) + 1
            self.note(
                f"velocities ({name}): RMS finite-difference residual {rel:.3g} of the RMS "
                f"velocity (worst frame {worst}: {residual[worst - 1]:.3g} {unit})"
            )
            if rel > VELOCITY_RELATIVE_TOLERANCE:
                self.problem(
                    f"{path}: {name} velocities disagree with gt/poses.txt by central finite "
                    f"differences (RMS residual {rel:.3g} of the RMS velocity > "
                    f"{VELOCITY_RELATIVE_TOLERANCE}; worst at frame {worst}, "
                    f"{residual[worst - 1]:.3g} {unit}); expected v_obj = d/dt t_cam_obj and "
                    "w in the camera frame"
                )

    # -------------------------------------------------------------------------- flows
    def _read_flow(self, path: Path) -> tuple[int, np.ndarray] | None:
        try:
            data = path.read_bytes()
        except OSError as e:
            self.problem(f"{path}: cannot read: {e}")
            return None
        if len(data) < 20:
            self.problem(f"{path}: {len(data)} bytes, shorter than the 20-byte header")
            return None
        cv_type, cols, rows = struct.unpack("<iQQ", data[:20])
        if cv_type not in (11, 13):
            self.problem(f"{path}: OpenCV type {cv_type}, expected 13 (CV_32FC2) or 11 (CV_16SC2)")
            return None
        if cols == 0 or rows == 0 or cols > self.width or rows > self.height:
            self.problem(f"{path}: header size {cols}x{rows} does not fit the image")
            return None
        grid = -(-self.width // cols)
        if (-(-self.height // grid), -(-self.width // grid)) != (rows, cols):
            self.problem(f"{path}: {cols}x{rows} is no whole-pixel grid over the image")
            return None
        item = 4 if cv_type == 13 else 2
        want = 20 + 2 * item * rows * cols
        if len(data) != want:
            self.problem(f"{path}: {len(data)} bytes, header says {want}")
            return None
        if cv_type == 13:
            flow = np.frombuffer(data, "<f4", offset=20).reshape(rows, cols, 2).astype(np.float64)
        else:
            flow = np.frombuffer(data, "<i2", offset=20).reshape(rows, cols, 2) / 32.0
        if not np.isfinite(flow).all():
            self.problem(f"{path}: NaN/inf flow values")
            return None
        return cv_type, flow

    def _check_flows(self) -> None:
        root = self.path / "optical_flow"
        if not root.is_dir():
            self.note("optical_flow/ absent")
            return
        for set_dir in sorted(p for p in root.iterdir() if p.is_dir()):
            if (set_dir / "0.float").exists():
                self.problem(
                    f"{set_dir / '0.float'}: flow file 0 must not exist (file k holds the flow "
                    "from frame k-1 to k)"
                )
            files = self._expect_indexed_files(set_dir, r"(\d+)\.float", range(1, self.n))
            types = set()
            flows: dict[int, np.ndarray] = {}
            for i, path in sorted(files.items()):
                parsed = self._read_flow(path)
                if parsed is not None:
                    types.add(parsed[0])
                    if i in self._flow_sample:
                        flows[i] = parsed[1]
            if len(types) > 1:
                self.problem(f"{set_dir}: files mix OpenCV types {sorted(types)}")
            self._check_flow_direction(set_dir, flows)

    def _motion_field(
        self, k: int, grid: int, flow_shape: tuple[int, ...], valid_png: Path | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Object pixels (rows, cols) of frame k and their motion field from k to k+1 [px]
        computed from the depth of frame k and the gt poses; None when unusable."""
        depth = self._depth_cache.get(k)
        if depth is None:
            return None
        mask_path = self.path / "masks" / "gt" / f"{self.object_name}_{k}.png"
        mask = cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE)
        if mask is None or mask.shape != depth.shape:
            return None
        rows, cols = np.nonzero((mask > 127) & (depth > 0))
        if valid_png is not None and valid_png.is_file():
            valid = cv2.imread(str(valid_png), cv2.IMREAD_GRAYSCALE)
            if valid is not None and valid.shape == flow_shape[:2]:
                keep = valid[rows // grid, cols // grid] > 127
                rows, cols = rows[keep], cols[keep]
        if rows.size < 10:
            return None
        step = max(1, rows.size // 2000)
        rows, cols = rows[::step], cols[::step]
        pix = np.stack([cols, rows, np.ones_like(rows)]).astype(np.float64)
        X = np.linalg.inv(self.K) @ pix * depth[rows, cols]
        assert self.gt_poses is not None  # the callers check it
        M = self.gt_poses[k + 1] @ np.linalg.inv(self.gt_poses[k])
        X1 = M[:3, :3] @ X + M[:3, 3:4]
        if (X1[2] <= 0).any():
            return None
        expected = ((self.K @ (X1 / X1[2]))[:2] - pix[:2]).T
        return rows, cols, expected

    def _check_flow_direction(self, set_dir: Path, flows: dict[int, np.ndarray]) -> None:
        """File i must hold the motion from frame i-1 to i: compared with the reversed flow
        and with the next pair (i -> i+1, an off-by-one writer)."""
        if self.gt_poses is None or not (self.path / "masks" / "gt").is_dir():
            self.note(f"{set_dir.name}: flow direction not checked (needs gt poses and masks)")
            return
        own_err, rev_err, motions, next_err, own_err_paired = [], [], [], [], []
        for i, flow in sorted(flows.items()):
            grid = -(-self.width // flow.shape[1])
            valid_png = self.path / "optical_flow_valid" / set_dir.name / f"{i}.png"
            own = self._motion_field(i - 1, grid, flow.shape, valid_png)
            if own is None:
                continue
            rows, cols, expected = own
            motion = float(np.median(np.linalg.norm(expected, axis=1)))
            if motion < FLOW_MIN_MOTION_PX:
                continue
            stored = flow[rows // grid, cols // grid]
            err = float(np.median(np.linalg.norm(stored - expected, axis=1)))
            motions.append(motion)
            own_err.append(err)
            rev_err.append(float(np.median(np.linalg.norm(stored + expected, axis=1))))
            if i + 1 < self.n:
                nxt = self._motion_field(i, grid, flow.shape, None)
                if nxt is not None:
                    r, c, e = nxt
                    next_err.append(
                        float(np.median(np.linalg.norm(flow[r // grid, c // grid] - e, axis=1)))
                    )
                    own_err_paired.append(err)
        if not own_err:
            self.note(f"{set_dir.name}: flow direction not checked (too little motion)")
            return
        fwd, rev = float(np.median(own_err)), float(np.median(rev_err))
        motion = float(np.median(motions))
        self.note(
            f"{set_dir.name}: flow vs. motion field of the gt poses over {len(own_err)} "
            f"frames: median error {fwd:.3g} px (a reversed flow would give {rev:.3g} px)"
        )
        if fwd >= rev:
            self.problem(
                f"{set_dir}: the flow looks reversed: it matches the motion from frame k to k-1 "
                f"({rev:.3g} px) better than from k-1 to k ({fwd:.3g} px); file k must hold "
                "the flow that maps frame k-1 to frame k"
            )
            return
        if next_err:
            paired, shifted = float(np.median(own_err_paired)), float(np.median(next_err))
            if shifted < 0.5 * paired:
                self.problem(
                    f"{set_dir}: file k seems to hold the flow from frame k to k+1 (median error "
                    f"{shifted:.3g} px) rather than from k-1 to k ({paired:.3g} px)"
                )
                return
        if fwd > 1.0 + 0.5 * motion:
            self.problem(
                f"{set_dir}: the flow disagrees with the ground-truth motion (median error "
                f"{fwd:.3g} px for a median motion of {motion:.3g} px); wrong frame pairing or "
                "units?"
            )

    def _check_models(self) -> None:
        models = self.path / "models"
        if not models.is_dir():
            self.note("models/ absent")
            return
        for d in sorted(p for p in models.iterdir() if p.is_dir()):
            points = d / "points.xyz"
            if not points.is_file():
                self.problem(f"{points}: missing (one 'x y z' row in metres per model point)")
                continue
            rows = _read_rows(points, 3, self.report.problems)
            if rows is not None and len(rows) == 0:
                self.problem(f"{points}: empty")
