"""DeclaredModel.load on a robot's URDF or MJCF, without a declared-model YAML: the joints the
truth commands, the end of the chain as the end effector, and forward kinematics equal to the
URDF's own chain of origins and axes (composed here with numpy)."""
import os
from pathlib import Path

import numpy as np

import flexbench

SOURCE = Path(os.environ.get("FLEXBENCH_SOURCE_DIR", Path(__file__).resolve().parents[2]))

URDF = """<?xml version="1.0"?>
<robot name="arm3">
  <link name="base"/>
  <joint name="j1" type="revolute">
    <origin xyz="0 0 0.1" rpy="0 0 0.3"/><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l1"><inertial><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j2" type="continuous">
    <origin xyz="0.25 0 0.05"/><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
  </joint>
  <link name="l2"><inertial><origin xyz="0.15 0 0"/><mass value="0.8"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.005" iyz="0" izz="0.005"/></inertial></link>
  <joint name="j3" type="revolute">
    <origin xyz="0.3 0 0" rpy="0.05 0 0"/><parent link="l2"/><child link="l3"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <link name="l3"><inertial><origin xyz="0.1 0 0"/><mass value="0.4"/>
    <inertia ixx="0.0003" ixy="0" ixz="0" iyy="0.0015" iyz="0" izz="0.0015"/></inertial></link>
  <joint name="tool_joint" type="fixed">
    <origin xyz="0.2 0 0"/><parent link="l3"/><child link="tool"/>
  </joint>
  <link name="tool"/>
</robot>
"""


def _rot(axis, a):
    x, y, z = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def _origin(xyz, rpy=(0, 0, 0)):
    T = np.eye(4)
    T[:3, :3] = _rot([0, 0, 1], rpy[2]) @ _rot([0, 1, 0], rpy[1]) @ _rot([1, 0, 0], rpy[0])
    T[:3, 3] = xyz
    return T


def _turn(axis, a):
    T = np.eye(4)
    T[:3, :3] = _rot(axis, a)
    return T


def _urdf_fk(q):
    return (_origin([0, 0, 0.1], [0, 0, 0.3]) @ _turn([0, 0, 1], q[0]) @
            _origin([0.25, 0, 0.05]) @ _turn([0, 1, 0], q[1]) @
            _origin([0.3, 0, 0], [0.05, 0, 0]) @ _turn([0, 1, 0], q[2]) @ _origin([0.2, 0, 0]))


def test_urdf_without_declared_yaml(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(URDF)
    model = flexbench.DeclaredModel.load(str(path))
    assert model.nq == 3
    assert model.joint_names == ["j1", "j2", "j3"]
    assert model.end_effector == "tool"
    assert model.model_path == str(path)
    rng = np.random.default_rng(3)
    for _ in range(10):
        q = rng.uniform(-2.0, 2.0, 3)
        assert np.allclose(model.fk(q, "tool"), _urdf_fk(q), rtol=0, atol=1e-12)
    # The default sources give the pose a covariance: 0.1 deg about each joint's axis.
    _, cov = model.fk_cov(np.zeros(3), "tool")
    assert np.all(np.isfinite(cov)) and np.trace(cov) > 0


def test_mjcf_without_declared_yaml():
    mjcf = flexbench.DeclaredModel.load(str(SOURCE / "models" / "planar3.xml"))
    declared = flexbench.DeclaredModel.load(str(SOURCE / "models" / "planar3.declared.yaml"))
    assert mjcf.joint_names == declared.joint_names
