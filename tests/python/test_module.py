"""The flexbench Python module against the C++ library and the CLI.

Run by ctest (label unit) as `python3 -m pytest tests/python` with PYTHONPATH=build/python and
FLEXBENCH_BIN_DIR=build/bin (python_reference prints the C++ results as hex floats; the
`flexbench` CLI prints the error lines the module's ValueErrors must repeat).
"""
import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import flexbench

SOURCE = Path(os.environ.get("FLEXBENCH_SOURCE_DIR", Path(__file__).resolve().parents[2]))
BIN = Path(os.environ.get("FLEXBENCH_BIN_DIR", SOURCE / "build" / "bin"))
DECLARED = str(SOURCE / "models" / "rover_arm.declared.yaml")


def _reference():
    out = subprocess.run([str(BIN / "python_reference"), DECLARED], check=True,
                         capture_output=True, text=True).stdout
    ref = {}
    for line in out.splitlines():
        name, rest = line.split(" ", 1)
        if name.endswith("_message") or name.startswith("status_"):
            ref[name] = rest
        else:
            n, *values = rest.split()
            assert int(n) == len(values)
            ref[name] = np.array([float.fromhex(v) for v in values])
    return ref


@pytest.fixture(scope="module")
def ref():
    return _reference()


@pytest.fixture(scope="module")
def model():
    return flexbench.DeclaredModel.load(DECLARED)


def _cli_error(*args):
    """The one error line the CLI prints for `flexbench <args>` (exit code 2)."""
    p = subprocess.run([str(BIN / "flexbench"), *args], capture_output=True, text=True,
                       cwd=SOURCE, timeout=300)
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = [l for l in p.stderr.splitlines() if l.startswith("flexbench: error: ")]
    assert len(lines) == 1, p.stderr
    return lines[0]


# ---- kinematics: bit-equal to the C++ calls ----------------------------------------------------

def test_model_properties(model):
    assert model.nq == 8
    assert model.joint_names == ["j1", "j2", "j3", "j4", "j5", "j6", "mast_pan", "mast_tilt"]
    assert model.end_effector == "ee"
    assert model.frame_id("ee") == model.frame_id(None) == model.frame_id("site/ee")


def test_fk_bit_equal(model, ref):
    T = model.fk(ref["q"], "ee")
    assert T.shape == (4, 4) and T.dtype == np.float64
    assert np.array_equal(T.ravel(), ref["fk"])
    J = model.jacobian(ref["q"], "ee")
    assert J.shape == (6, 8)
    assert np.array_equal(J.ravel(), ref["jacobian"])


@pytest.mark.parametrize("order", [2, 4])
def test_fk_cov_bit_equal(model, ref, order):
    T, S = model.fk_cov(ref["q"], "ee", order=order)
    assert T.shape == (4, 4) and S.shape == (6, 6)
    assert np.array_equal(T.ravel(), ref[f"fk_cov{order}_T"])
    assert np.array_equal(S.ravel(), ref[f"fk_cov{order}_S"])
    assert np.any(S != 0.0)


def test_fk_cov_orders_differ(model, ref):
    # The comparison above is not vacuous: 2nd and 4th order give different covariances.
    _, S2 = model.fk_cov(ref["q"], order=2)
    _, S4 = model.fk_cov(ref["q"], order=4)
    assert not np.array_equal(S2, S4)


def test_q_strided_and_list(model, ref):
    q = ref["q"]
    wide = np.zeros(2 * len(q))
    wide[::2] = q
    assert np.array_equal(model.fk_cov(wide[::2])[1], model.fk_cov(q)[1])
    assert np.array_equal(model.fk(list(q)), model.fk(q))


# ---- estimators ------------------------------------------------------------------------------

def test_ekf_update_matches_cpp(model, ref):
    q = ref["q"]
    est = flexbench.make_estimator("ppoe_ekf", model, covariance_order=2)
    est.predict(0.5)
    assert est.update_joints(0.5, q, 1e-3) == ref["status_joints"]
    p = model.fk(q)[:3, 3] + np.array([0.01, -0.005, 0.003])
    status = est.update_position(0.5, None, np.zeros(3), p, 1e-4 * np.eye(3))
    assert status == ref["status_position"] == "accepted"
    T, cov = est.estimate()
    np.testing.assert_allclose(T.ravel(), ref["ekf_T"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(cov.ravel(), ref["ekf_cov"], rtol=0, atol=1e-12)
    # The update moved the estimate off the prior.
    assert np.linalg.norm(T[:3, 3] - model.fk(q)[:3, 3]) > 1e-3


def test_estimator_names():
    names = flexbench.estimator_names()
    assert "ppoe_ekf" in names and "fk" in names


# ---- bad input: ValueError, never a crash -----------------------------------------------------

def test_bad_q_shape(model, ref):
    with pytest.raises(ValueError, match=r"q: expected shape \(8,\), got shape \(2, 4\)"):
        model.fk_cov(np.zeros((2, 4)))
    # A wrong length is the library's own message.
    with pytest.raises(ValueError) as e:
        model.fk(np.zeros(3))
    assert str(e.value) == ref["size_message"]


@pytest.mark.parametrize("q", [np.zeros(8, dtype=np.int64), np.zeros(8, dtype=np.float32),
                               np.zeros(8, dtype=complex), "abcdefgh", None, {"a": 1}])
def test_bad_q_dtype(model, q):
    with pytest.raises(ValueError, match=r"^q: expected"):
        model.fk_cov(q)


def test_nan_joint_angle(model, ref):
    q = ref["q"].copy()
    q[2] = math.nan
    for call, message in ((model.fk, "nan_message"), (model.fk_cov, "nan_cov_message"),
                          (model.jacobian, "nan_message")):
        with pytest.raises(ValueError) as e:
            call(q)
        assert str(e.value) == ref[message]
    assert "nan" in ref["nan_message"].lower() or "finite" in ref["nan_message"].lower()


def test_bad_frame_and_order(model, ref):
    with pytest.raises(ValueError, match="no frame 'nowhere'"):
        model.fk(ref["q"], "nowhere")
    with pytest.raises(ValueError, match="out of range"):
        model.fk(ref["q"], 10_000)
    with pytest.raises(ValueError, match="order: expected 2 or 4"):
        model.fk_cov(ref["q"], order=3)


def test_bad_measurement_shapes(model, ref):
    est = flexbench.make_estimator("ppoe_ekf", model)
    with pytest.raises(ValueError, match=r"p_base: expected shape \(3,\)"):
        est.update_position(0.0, None, np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match=r"cov: expected shape \(3, 3\)"):
        est.update_position(0.0, None, np.zeros(3), np.zeros(3), np.eye(2))
    with pytest.raises(ValueError, match=r"T_base_frame: .*not a rotation"):
        est.update_pose(0.0, None, 2 * np.eye(4))
    # NaN readings are a sensor's fault, not a caller's: the estimator rejects them.
    assert est.update_joints(0.0, np.full(8, math.nan), 1e-3) == "rejected_non_finite"


# The CLI is given the same parameters with --set on a scenario that has `estimators:` but not
# the one named; its error line must be "flexbench: error: " + the ValueError's message.
CLI_SCENARIO = "scenarios/humanoid_table_contact.yaml"


def test_unknown_estimator_same_message_as_cli(model):
    with pytest.raises(ValueError) as e:
        flexbench.make_estimator("kalman_magic", model)
    cli = _cli_error("run", CLI_SCENARIO, "--out", "/tmp/flexbench_py_never", "--quiet",
                     "--set", "estimators.kalman_magic={}")
    assert cli == "flexbench: error: " + str(e.value)
    assert "unknown estimator 'kalman_magic'" in str(e.value)


def test_unknown_parameter_same_message_as_cli(model):
    with pytest.raises(ValueError) as e:
        flexbench.make_estimator("pf_encoders", model, covariance_ordr=2)
    cli = _cli_error("run", CLI_SCENARIO, "--out", "/tmp/flexbench_py_never", "--quiet",
                     "--set", "estimators.pf_encoders.covariance_ordr=2")
    assert cli == "flexbench: error: " + str(e.value)
    assert "unknown parameter 'covariance_ordr'" in str(e.value)


def test_bad_parameter_value_same_message_as_cli(model):
    with pytest.raises(ValueError) as e:
        flexbench.make_estimator("pf_encoders", model, kappa_w="lots")
    cli = _cli_error("run", CLI_SCENARIO, "--out", "/tmp/flexbench_py_never", "--quiet",
                     "--set", "estimators.pf_encoders.kappa_w=lots")
    assert cli == "flexbench: error: " + str(e.value)


# ---- run_scenario ------------------------------------------------------------------------------

def test_run_scenario_smoke(tmp_path):
    out = tmp_path / "smoke"
    summary = flexbench.run_scenario(str(SOURCE / "scenarios" / "smoke.yaml"), str(out), seed=7,
                                     overrides={"detector.threads": 1, "render.mode": "quality"})
    assert summary == json.loads((out / "summary.json").read_text())
    assert summary["scenario"] == "smoke"
    assert summary["seed"] == 7
    assert summary["overrides"] == ["detector.threads=1", "render.mode=quality"]
    assert all(g["passed"] for g in summary["gates"])


def test_run_scenario_bad_override_same_message_as_cli(tmp_path):
    with pytest.raises(ValueError) as e:
        flexbench.run_scenario(str(SOURCE / "scenarios" / "smoke.yaml"), str(tmp_path / "x"),
                               overrides={"detector.famly": "tag36h11"})
    cli = _cli_error("run", str(SOURCE / "scenarios" / "smoke.yaml"), "--out",
                     str(tmp_path / "y"), "--quiet", "--set", "detector.famly=tag36h11")
    assert cli == "flexbench: error: " + str(e.value)
    assert not (tmp_path / "x").exists()


def test_run_scenario_missing_file(tmp_path):
    with pytest.raises(ValueError) as e:
        flexbench.run_scenario(str(tmp_path / "none.yaml"), str(tmp_path / "x"))
    cli = _cli_error("run", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "y"), "--quiet")
    assert cli == "flexbench: error: " + str(e.value)


def test_identify_bad_input_same_message_as_cli(tmp_path):
    csv = str(tmp_path / "missing.csv")
    with pytest.raises(ValueError) as e:
        flexbench.identify(DECLARED, csv, csv, out=str(tmp_path / "id"))
    cli = _cli_error("identify", "--declared", DECLARED, "--calibration", csv, "--validation",
                     csv, "--out", str(tmp_path / "id2"), "--quiet")
    assert cli == "flexbench: error: " + str(e.value)
    assert "--calibration" in str(e.value)


def _find_key(d, key):
    if isinstance(d, dict):
        if key in d:
            return d[key]
        for v in d.values():
            r = _find_key(v, key)
            if r is not None:
                return r
    return None


def test_identify_finds_a_joint_offset(tmp_path):
    # Measured end-effector points of planar3 whose joint2 reads 0.01 rad off: identify, like
    # `flexbench identify`, names the effect.
    declared = str(SOURCE / "models" / "planar3.declared.yaml")
    model = flexbench.DeclaredModel.load(declared)
    rng = np.random.default_rng(4)
    for name in ("cal.csv", "val.csv"):
        rows = ["joint1,joint2,joint3,x,y,z"]
        for _ in range(40):
            q = rng.uniform(-1.2, 1.2, 3)
            p = model.fk(q + np.array([0.0, 0.01, 0.0]))[:3, 3] + rng.normal(0, 1e-4, 3)
            rows.append(",".join(f"{v:.12g}" for v in [*q, *p]))
        (tmp_path / name).write_text("\n".join(rows) + "\n")
    summary = flexbench.identify(declared, str(tmp_path / "cal.csv"), str(tmp_path / "val.csv"),
                                 out=str(tmp_path / "out"), overrides={"max_effects": 2})
    assert summary["overrides"] == ["max_effects=2"]
    assert _find_key(summary, "effects_found") == ["joint_offset@joint2"], summary


@pytest.mark.parametrize("kwargs, message", [
    ({"estimate_in": 3}, "estimate_in: expected a str"),
    ({"estimate_in": "nowhere"}, "nowhere"),
    ({"camera_frames": "mast_camera"}, "camera_frames: expected a list"),
    ({"camera_frames": ["nope"]}, "no camera named 'nope'"),
    ({"seed": -1}, "seed: expected an int >= 0"),
    ({"covariance_order": object()}, "cannot express a value of type object"),
    ({"covariance_order": 3}, "covariance_order must be 2 or 4"),
])
def test_bad_setup_arguments(model, kwargs, message):
    with pytest.raises(ValueError, match=message):
        flexbench.make_estimator("ppoe_ekf", model, **kwargs)


def test_estimator_in_camera_frame(model, ref):
    est = flexbench.make_estimator("ppoe_ekf", model, camera_frames=["mast_camera"],
                                   estimate_in="mast_camera")
    assert est.update_joints(0.0, ref["q"], 1e-3) == "accepted"
    T, cov = est.estimate()
    # The prior is the end effector seen from the camera: T_cam_ee = T_base_cam^-1 T_base_ee.
    T_cam = model.fk(ref["q"], "mast_camera")
    np.testing.assert_allclose(T, np.linalg.solve(T_cam, model.fk(ref["q"])), atol=1e-12)
    assert est.belief()["q"].shape == (8,)


@pytest.mark.parametrize("content", [None, "actuated_joints: [j1, jx]\nend_effector: ee\n"])
def test_load_bad_declared_same_message_as_cli(tmp_path, content):
    # A missing declared file, or one naming a joint the model lacks: the message `flexbench
    # run` prints for a scenario given that file.
    path = tmp_path / "robot.declared.yaml"
    if content is not None:
        path.write_text(f"model: {SOURCE / 'models' / 'rover_arm.xml'}\n" + content)
    with pytest.raises(ValueError) as e:
        flexbench.DeclaredModel.load(str(path))
    cli = _cli_error("run", "scenarios/rover_apriltag_exp1.yaml", "--out", str(tmp_path / "o"),
                     "--quiet", "--set", f"declared={path}")
    assert cli == "flexbench: error: " + str(e.value)


GARBAGE = [None, "x", 1.5, [1.0, 2.0], np.zeros((3, 3)), np.zeros(7, dtype=np.int32),
           np.full(3, np.nan), {"a": 1}, object()]


def test_garbage_never_crashes(model, ref):
    # Every entry point given nonsense in every array slot raises a Python exception (ValueError
    # for bad values, TypeError where pybind11 rejects an argument's type); none takes the
    # interpreter down.
    est = flexbench.make_estimator("ppoe_ekf", model)
    q = ref["q"]
    calls = [
        lambda g: model.fk(g), lambda g: model.fk_cov(g), lambda g: model.jacobian(g),
        lambda g: model.fk(q, g), lambda g: model.fk_cov(q, "ee", g),
        lambda g: est.update_joints(0.0, g, 1e-3), lambda g: est.update_joints(0.0, q, g),
        lambda g: est.update_imu(0.0, g, np.zeros(3)),
        lambda g: est.update_orientation(0.0, "ee", g),
        lambda g: est.update_pixel(0.0, "ee", np.zeros(3), g),
        lambda g: est.update_tag(0.0, "ee", g, np.zeros((4, 2))),
        lambda g: est.update_contact(0.0, "ee", np.zeros(3), g),
        lambda g: est.update_position(0.0, g, np.zeros(3), np.zeros(3)),
        lambda g: est.update_pose(0.0, "ee", np.eye(4), g),
        lambda g: flexbench.make_estimator(g, model),
        lambda g: flexbench.make_estimator("ppoe_ekf", g),
        lambda g: flexbench.run_scenario(g, "/nonexistent/out"),
        lambda g: flexbench.run_scenario(str(SOURCE / "scenarios" / "smoke.yaml"),
                                         "/nonexistent/out", overrides=g),
    ]
    for call in calls:
        for g in GARBAGE:
            try:
                call(g)
            except (ValueError, TypeError):
                pass
    # Still alive and still right.
    assert np.array_equal(model.fk_cov(q)[1].ravel(), ref["fk_cov2_S"])


def test_raw_imu_readings_reach_the_estimators_that_use_them(model):
    # pf_encoders_imu and direct fusion run each IMU's Madgwick filter on update_imu; the EKF has
    # no use for them. A bad IMU index or filter option is a ValueError.
    up = [0.0, 0.0, 9.81]
    pf = flexbench.make_estimator("pf_encoders_imu", model, imu_frames=["ee"], particles=64,
                                  imu_beta=0.1)
    ekf = flexbench.make_estimator("ppoe_ekf", model, imu_frames=["ee"])
    assert ekf.update_imu(0.0, [0.0, 0.0, 0.0], up) == "ignored"
    assert pf.update_imu(0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]) == "rejected_outside"  # no "up"
    assert pf.update_imu(0.0, [0.0, 0.0, 0.0], up) == "accepted"
    assert pf.update_imu(0.005, [0.0, 0.0, 0.1], up) == "accepted"
    assert pf.update_imu(0.001, [0.0, 0.0, 0.1], up) == "rejected_outside"  # back in time
    assert pf.update_imu(0.01, [math.nan, 0.0, 0.0], up) == "rejected_non_finite"
    with pytest.raises(ValueError, match="IMU 1"):
        pf.update_imu(0.01, [0.0, 0.0, 0.0], up, imu=1)
    with pytest.raises(ValueError, match="imu_beta"):
        flexbench.make_estimator("pf_encoders_imu", model, imu_frames=["ee"], imu_beta=0.0)
    with pytest.raises(ValueError, match="imu_initial"):
        flexbench.make_estimator("pf_encoders_imu", model, imu_frames=["ee"],
                                 imu_initial=[[1, 0, 0, 0], [1, 0, 0, 0]])
    flexbench.make_estimator("pf_encoders_imu", model, imu_frames=["ee"],
                             imu_initial=[[1.0, 0.0, 0.0, 0.0]])
