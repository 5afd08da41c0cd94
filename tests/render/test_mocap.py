"""set_mocap_pose against MuJoCo's own forward kinematics and scipy's rotations."""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from roft_sim.render.mocap import set_mocap_pose

_XML = """<mujoco><worldbody>
<body name="a" mocap="true"><geom size="0.1"/></body>
<body name="b" mocap="true"><geom size="0.1"/></body>
</worldbody></mujoco>"""


def test_set_mocap_pose_places_the_body_at_the_transform():
    model = mujoco.MjModel.from_xml_string(_XML)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(7)
    poses = {}
    for name in ("a", "b"):
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        T[:3, 3] = rng.normal(size=3)
        poses[name] = T
        set_mocap_pose(data, int(model.body(name).mocapid[0]), T)
    mujoco.mj_kinematics(model, data)
    for name, T in poses.items():
        np.testing.assert_allclose(data.body(name).xpos, T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(data.body(name).xmat.reshape(3, 3), T[:3, :3], atol=1e-9)
