"""The articulated hand: an ``MjSpec`` hand, a grasp synthesised against the object with MuJoCo's
own distance queries, and seeded finger motion that never enters the object.

Hand frame ``hand`` (the mocap body ``hand``): the palm's inner surface is the plane z = 0, the
palm faces +z (towards the object), the fingers point along +y from the knuckle line
``y = palm_length / 2``, the thumb sits on the -x side. Every digit is a chain of three capsules
on hinges about its local x axis; a positive angle flexes the digit towards +z. Joint angles are
0 (straight) to the digit's ``flexion_limits_rad``.

Grasp synthesis (:func:`synthesise_grasp`), in the object frame:

1. a side is drawn: the palm's normal along one object axis ``a`` (the object's extent along it
   must fit within the fingers' reach, when any axis does; with ``side = "away_from_camera"``
   among the sides that face away from the camera over the sequence, as when a person holds an
   object up to a camera), the fingers along another axis ``b``, the knuckle line near the
   object's edge along ``b``, a small random tilt;
2. the open hand approaches along its +z until its nearest geom is ``contact_gap_m`` from the
   object (:func:`mujoco.mj_geomDistance`);
3. each digit closes joint by joint, proximal first: the joint flexes in 3 degree steps until a
   segment it moves would come nearer than ``contact_gap_m``, then bisects to the contact.

MuJoCo measures distances to the convex hull of a mesh, which contains the mesh, so a hand that
does not enter the hull does not enter the mesh either (concave parts leave a gap).

During the sequence (:class:`FingerMotion`) every digit only opens from the grasp (slow flexion
changes and re-grips drawn from the scenario's ``hand`` stream); a frame whose planned opening
would move a segment into the object opens that digit less (bisection on the opening, checked
with the same distance queries), so no frame interpenetrates.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry import matrix_from_rotvec, quat_from_matrix
from roft_sim.render.mocap import set_mocap_pose
from roft_sim.scene.config import FingerConfig, HandConfig, HandMotionConfig

F64 = NDArray[np.float64]

__all__ = [
    "HAND_BODY_PREFIX",
    "HandGrasp",
    "HandModel",
    "FingerMotion",
    "add_articulated_hand",
    "synthesise_grasp",
]

HAND_BODY_PREFIX = "hand"
"""Name of the hand's root body; its links are ``hand_<digit>_<segment>``."""

_SEGMENT_RADIUS_SCALE = (1.0, 0.93, 0.86)
_JOINT_WEIGHTS = np.array([0.45, 0.35, 0.2])
"""How a digit's opening is shared among its three joints (proximal to distal)."""
_THUMB_YAW_RAD = np.radians(40.0)
"""The thumb's metacarpal leans from +y towards -x by this angle, in the palm plane."""
_CLOSE_STEP_RAD = np.radians(3.0)
_MAX_DISTANCE_M = 1.0


def _digits(config: HandConfig) -> tuple[FingerConfig, ...]:
    return (*config.fingers, config.thumb_digit)


def add_articulated_hand(spec: mujoco.MjSpec, config: HandConfig, material: str) -> None:
    """Adds the hand to ``spec``: a mocap body ``hand`` with the palm box and, per digit, three
    bodies ``hand_<digit>_<i>`` with a hinge ``hand_<digit>_j<i>`` and a capsule geom each.

    Geoms do not collide (the scene is replayed kinematically); distances are asked explicitly.
    """
    root = spec.worldbody.add_body(name=HAND_BODY_PREFIX, mocap=True)
    length, width, thick = config.palm_length_m, config.palm_width_m, config.palm_thickness_m
    root.add_geom(
        name="hand_palm",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[width / 2, length / 2, thick / 2],
        pos=[0.0, 0.0, -thick / 2],
        material=material,
        contype=0,
        conaffinity=0,
    )
    n = len(config.fingers)
    for i, finger in enumerate(config.fingers):
        x = -width / 2 + width * (i + 0.5) / n
        base = [x, length / 2 - finger.radius_m, -finger.radius_m]
        _add_digit(root, finger, base, np.array([1.0, 0.0, 0.0, 0.0]), material)
    thumb = config.thumb_digit
    yaw = quat_from_matrix(matrix_from_rotvec(np.array([0.0, 0.0, _THUMB_YAW_RAD])))
    base = [-width / 2 + thumb.radius_m, -length / 2 + 0.3 * length, -thumb.radius_m]
    _add_digit(root, thumb, base, yaw, material)


def _add_digit(
    parent: mujoco.MjsBody, digit: FingerConfig, base_m: list[float], quat: F64, material: str
) -> None:
    body = parent
    pos, q = list(base_m), [float(v) for v in quat]
    for i, (seg_len, scale) in enumerate(zip(digit.lengths_m, _SEGMENT_RADIUS_SCALE, strict=True)):
        body = body.add_body(name=f"hand_{digit.name}_{i}", pos=pos, quat=q)
        body.add_joint(
            name=f"hand_{digit.name}_j{i}",
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[1.0, 0.0, 0.0],
            range=[0.0, float(digit.flexion_limits_rad[i])],
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        )
        body.add_geom(
            name=f"hand_{digit.name}_{i}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0.0, 0.0, 0.0, 0.0, seg_len, 0.0],
            size=[digit.radius_m * scale, 0.0, 0.0],
            material=material,
            contype=0,
            conaffinity=0,
        )
        pos, q = [0.0, seg_len, 0.0], [1.0, 0.0, 0.0, 0.0]


@dataclass(frozen=True, slots=True)
class HandModel:
    """Indices of the compiled hand in a model."""

    mocap: int
    """Mocap index of the root body ``hand``."""
    body_ids: tuple[int, ...]
    """MuJoCo body ids of the hand's rigid links: the root (palm) first, then every segment."""
    palm_geom: int
    """Geom id of the palm box."""
    digit_qpos: tuple[tuple[int, int, int], ...]
    """Per digit (fingers then thumb), the qpos addresses of its three joints."""
    digit_geoms: tuple[tuple[int, int, int], ...]
    """Per digit, the geom ids of its three segments, proximal to distal."""
    joint_limits_rad: F64
    """(D, 3) upper flexion limit of each joint [rad] (the lower one is 0)."""

    @classmethod
    def from_model(cls, model: mujoco.MjModel, config: HandConfig) -> HandModel:
        """Finds the hand added by :func:`add_articulated_hand` in a compiled model."""
        root = model.body(HAND_BODY_PREFIX).id
        bodies = [root]
        qpos, geoms, limits = [], [], []
        for digit in _digits(config):
            qpos.append(
                tuple(
                    int(model.jnt_qposadr[model.joint(f"hand_{digit.name}_j{i}").id])
                    for i in range(3)
                )
            )
            geoms.append(tuple(int(model.geom(f"hand_{digit.name}_{i}").id) for i in range(3)))
            bodies.extend(int(model.body(f"hand_{digit.name}_{i}").id) for i in range(3))
            limits.append(digit.flexion_limits_rad)
        return cls(
            mocap=int(model.body_mocapid[root]),
            body_ids=tuple(bodies),
            palm_geom=int(model.geom("hand_palm").id),
            digit_qpos=tuple(qpos),  # type: ignore[arg-type]
            digit_geoms=tuple(geoms),  # type: ignore[arg-type]
            joint_limits_rad=np.asarray(limits, dtype=np.float64),
        )

    @property
    def n_digits(self) -> int:
        """Number of digits (fingers and thumb)."""
        return len(self.digit_qpos)

    def set_angles(self, data: mujoco.MjData, angles_rad: F64) -> None:
        """Writes ``angles_rad`` (D, 3) [rad] into ``data.qpos``."""
        for adr, q in zip(self.digit_qpos, angles_rad, strict=True):
            data.qpos[list(adr)] = q

    def min_distance_m(
        self, model: mujoco.MjModel, data: mujoco.MjData, geoms: tuple[int, ...], target: int
    ) -> float:
        """Smallest signed distance [m] between ``geoms`` and the geom ``target`` (negative =
        penetration), after ``mj_kinematics`` has placed them."""
        return min(
            float(mujoco.mj_geomDistance(model, data, g, target, _MAX_DISTANCE_M, None))
            for g in geoms
        )


@dataclass(frozen=True, slots=True)
class HandGrasp:
    """A synthesised grasp: where the hand is on the object and how its digits are flexed."""

    T_obj_hand: F64
    """(4, 4) pose of the hand frame in the object frame [m]."""
    angles_rad: F64
    """(D, 3) joint angles of the digits at the grasp [rad]."""
    in_contact: tuple[bool, ...]
    """Per digit: it stopped on the object (False: it closed to its limits without touching)."""


def _place(model: mujoco.MjModel, data: mujoco.MjData, hand: HandModel, T_obj_hand: F64) -> None:
    set_mocap_pose(data, hand.mocap, T_obj_hand)
    mujoco.mj_kinematics(model, data)


def _all_geoms(hand: HandModel) -> tuple[int, ...]:
    return (hand.palm_geom, *(g for digit in hand.digit_geoms for g in digit))


def _draw_side(
    half_extents_m: F64,
    reach_m: float,
    rng: np.random.Generator,
    camera_dirs_obj: F64 | None = None,
) -> tuple[int, float, int, float]:
    """(palm axis a, its sign, finger axis b, its sign): the palm's normal lies along a, where
    the object's extent fits within the fingers' reach when any axis does. With
    ``camera_dirs_obj`` (N, 3) (unit directions from the object to the camera over the
    sequence, object frame), only the sides facing away from the camera are drawn from: those
    whose mean ``-normal . direction`` is within 0.25 of the best side's."""
    fits = [a for a in range(3) if 2.0 * half_extents_m[a] <= reach_m]
    axes = fits if fits else [0, 1, 2]
    sides = [(a, sign) for a in axes for sign in (-1.0, 1.0)]
    if camera_dirs_obj is not None and len(camera_dirs_obj):
        away = np.array([-sign * float(camera_dirs_obj[:, a].mean()) for a, sign in sides])
        sides = [
            side for side, score in zip(sides, away, strict=True) if score >= away.max() - 0.25
        ]
    a, sa = sides[int(rng.integers(len(sides)))]
    b = int(rng.choice([i for i in range(3) if i != a]))
    return a, sa, b, float(rng.choice([-1.0, 1.0]))


def synthesise_grasp(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    hand: HandModel,
    object_geom: int,
    object_mocap: int,
    half_extents_m: F64,
    config: HandConfig,
    rng: np.random.Generator,
    camera_dirs_obj: F64 | None = None,
) -> HandGrasp:
    """Places the hand on a side of the object and closes its digits onto it (module doc).

    Args:
        model, data: a compiled scene holding the object and the hand; ``data`` is used as
            scratch (the object is put at the origin).
        hand: the hand's indices in ``model``.
        object_geom: geom id of the object mesh.
        object_mocap: mocap index of the object body.
        half_extents_m: (3,) half extents of the object's bounding box about its origin,
            object frame [m].
        config: the hand.
        rng: draws the side, the offsets and the tilt.
        camera_dirs_obj: (N, 3) unit directions from the object to the camera over the sequence,
            object frame; given, the palm goes on a side facing away from the camera
            (``side = "away_from_camera"``). None: any side.

    Returns:
        The grasp; no hand geom is nearer the object than ``config.contact_gap_m`` minus the
        bisection's resolution (far below 0.1 mm).
    """
    e = np.asarray(half_extents_m, dtype=np.float64)
    set_mocap_pose(data, object_mocap, np.eye(4))
    data.qpos[:] = 0.0
    reach = 0.85 * float(sum(config.fingers[len(config.fingers) // 2].lengths_m))
    a, sa, b, sb = _draw_side(e, reach, rng, camera_dirs_obj)
    z_hand = np.zeros(3)
    z_hand[a] = -sa
    y_hand = np.zeros(3)
    y_hand[b] = sb
    R = np.column_stack([np.cross(y_hand, z_hand), y_hand, z_hand])
    R = R @ matrix_from_rotvec(rng.uniform(-0.12, 0.12, 3))
    c = 3 - a - b
    offset = np.zeros(3)
    offset[b] = sb * (e[b] - config.palm_length_m / 2 - rng.uniform(0.0, 0.015))
    offset[c] = rng.uniform(-1.0, 1.0) * 0.5 * max(e[c] - config.palm_width_m / 2, 0.0)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = offset - R[:, 2] * (np.linalg.norm(e) + 0.05)
    gap = config.contact_gap_m
    geoms = _all_geoms(hand)
    for _ in range(20):  # approach along the hand's +z until the nearest geom is `gap` away
        _place(model, data, hand, T)
        d = hand.min_distance_m(model, data, geoms, object_geom)
        if abs(d - gap) < 1e-5:
            break
        T[:3, 3] += R[:, 2] * (d - gap) * (0.9 if d > gap else 1.0)
    angles = np.zeros((hand.n_digits, 3))
    contact = []
    for i in range(hand.n_digits):
        touched = _close_digit(model, data, hand, i, angles, object_geom, gap)
        contact.append(touched)
    hand.set_angles(data, angles)
    mujoco.mj_kinematics(model, data)
    return HandGrasp(T_obj_hand=T, angles_rad=angles, in_contact=tuple(contact))


def _close_digit(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    hand: HandModel,
    digit: int,
    angles: F64,
    object_geom: int,
    gap_m: float,
) -> bool:
    """Flexes digit ``digit``'s joints in turn, proximal first, each until a segment it moves
    would come nearer the object than ``gap_m`` or its limit; writes ``angles[digit]``."""
    touched = False

    def clearance(j: int, value: float) -> float:
        angles[digit, j] = value
        hand.set_angles(data, angles)
        mujoco.mj_kinematics(model, data)
        return hand.min_distance_m(model, data, hand.digit_geoms[digit][j:], object_geom)

    for j in range(3):
        limit = float(hand.joint_limits_rad[digit, j])
        good = 0.0
        if clearance(j, 0.0) < gap_m:  # already touching (an earlier joint stopped on contact)
            angles[digit, j] = 0.0
            touched = True
            continue
        bad = None
        value = 0.0
        while value < limit:
            value = min(value + _CLOSE_STEP_RAD, limit)
            if clearance(j, value) < gap_m:
                bad = value
                break
            good = value
        if bad is not None:
            touched = True
            for _ in range(14):
                mid = 0.5 * (good + bad)
                if clearance(j, mid) < gap_m:
                    bad = mid
                else:
                    good = mid
        angles[digit, j] = good
    return touched


class FingerMotion:
    """The seeded opening of each digit from the grasp over time, and its collision-free
    application (module doc).

    Opening of digit ``i`` at time t [s] (>= 0, [rad]):
    ``jitter * (1 - cos(2 pi f_i t + phi_i)) / 2`` plus, for every re-grip ``(t_e, digits)`` that
    includes it, ``regrip_opening * (1 - cos(2 pi (t - t_e) / duration)) / 2`` while
    ``t_e <= t <= t_e + duration``. A digit's opening is shared among its joints
    (0.45, 0.35, 0.2), proximal to distal, and never takes a joint below 0.

    Args:
        config: the motion model.
        grasp: the grasp the digits open from.
        duration_s: length of the sequence [s] (re-grips are drawn up to it).
        rng: draws frequencies, phases and re-grips (all at construction).
    """

    def __init__(
        self,
        config: HandMotionConfig,
        grasp: HandGrasp,
        duration_s: float,
        rng: np.random.Generator,
    ) -> None:
        d = grasp.angles_rad.shape[0]
        self.config = config
        self.grasp = grasp
        self.frequency_hz = config.jitter_frequency_hz * rng.uniform(0.5, 1.5, d)
        """(D,) frequency of each digit's slow flexion change [Hz]."""
        self.phase_rad = rng.uniform(0.0, 2.0 * np.pi, d)
        """(D,) phase of each digit's slow flexion change [rad]."""
        n_events = int(rng.poisson(config.regrip_rate_hz * max(duration_s, 0.0)))
        starts = np.sort(rng.uniform(0.0, max(duration_s, 0.0), n_events))
        digits = rng.random((n_events, d)) < 0.5
        digits[np.arange(n_events), rng.integers(0, d, n_events)] = True
        self.regrip_start_s = starts
        """(E,) start times of the re-grips [s]."""
        self.regrip_digits = digits
        """(E, D) which digits take part in each re-grip."""

    def opening_rad(self, t_s: float) -> F64:
        """(D,) planned opening of each digit at time ``t_s`` [s] (before the collision check)."""
        c = self.config
        phase = 2.0 * np.pi * self.frequency_hz * t_s + self.phase_rad
        opening = c.flexion_jitter_rad * 0.5 * (1.0 - np.cos(phase))
        u = (t_s - self.regrip_start_s) / c.regrip_duration_s
        active = (u >= 0.0) & (u <= 1.0)
        bump = np.where(active, 0.5 * (1.0 - np.cos(2.0 * np.pi * u)), 0.0)
        regrips = c.regrip_opening_rad * (bump[:, None] * self.regrip_digits).sum(axis=0)
        return np.asarray(opening + regrips, dtype=np.float64)

    def planned_angles_rad(self, t_s: float, scale: F64 | None = None) -> F64:
        """(D, 3) joint angles [rad] for the planned opening at ``t_s``, each digit's opening
        multiplied by ``scale`` (D,) (default 1)."""
        opening = self.opening_rad(t_s) if scale is None else self.opening_rad(t_s) * scale
        angles = np.maximum(self.grasp.angles_rad - opening[:, None] * _JOINT_WEIGHTS, 0.0)
        return np.asarray(angles, dtype=np.float64)

    def pose(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        hand: HandModel,
        object_geom: int,
        t_s: float,
    ) -> F64:
        """Sets the hand's joints for time ``t_s`` without entering the object and runs
        ``mj_kinematics``; the hand's root and the object must already be placed in ``data``.

        Returns:
            (D, 3) the joint angles set [rad].
        """
        scale = np.ones(hand.n_digits)
        angles = self.planned_angles_rad(t_s)
        hand.set_angles(data, angles)
        mujoco.mj_kinematics(model, data)
        for i in range(hand.n_digits):
            geoms = hand.digit_geoms[i]
            if hand.min_distance_m(model, data, geoms, object_geom) >= 0.0:
                continue
            lo, hi = 0.0, 1.0  # the grasp (scale 0) is clear of the object
            for _ in range(10):
                scale[i] = 0.5 * (lo + hi)
                angles = self.planned_angles_rad(t_s, scale)
                hand.set_angles(data, angles)
                mujoco.mj_kinematics(model, data)
                if hand.min_distance_m(model, data, geoms, object_geom) >= 0.0:
                    lo = scale[i]
                else:
                    hi = scale[i]
            scale[i] = lo
        angles = self.planned_angles_rad(t_s, scale)
        hand.set_angles(data, angles)
        mujoco.mj_kinematics(model, data)
        return angles
