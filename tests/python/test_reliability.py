"""The Python module never takes the interpreter down, and refuses what would spoil a result.

Each hazard runs in a child interpreter (`_child`): a crash there is this test's failure with the
child's exit code and output, not the end of the whole suite. Run by ctest with the rest of
tests/python (PYTHONPATH=build/python).
"""
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import flexbench

SOURCE = Path(os.environ.get("FLEXBENCH_SOURCE_DIR", Path(__file__).resolve().parents[2]))
SMOKE = str(SOURCE / "scenarios" / "smoke.yaml")
DECLARED = str(SOURCE / "models" / "rover_arm.declared.yaml")


def _child(code, timeout=600):
    """Runs `code` in a fresh interpreter with flexbench importable; (exit code, stdout+stderr)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                       text=True, timeout=timeout, env=env, cwd=SOURCE)
    return p.returncode, p.stdout + p.stderr


def _leftovers(out):
    """Anything of `out` or its temporaries next to it."""
    return sorted(str(p) for p in Path(out).parent.glob(Path(out).name + "*"))


# ---- the interpreter --------------------------------------------------------------------------

def test_an_interpreter_without_numpy_is_told_which_one_it_is():
    code, out = _child("""
        import sys
        sys.modules['numpy'] = None  # as in an interpreter that has no numpy
        import flexbench
    """)
    assert code != 0
    assert "flexbench needs numpy, which the interpreter importing it (" + sys.executable in out, out


# ---- overrides: cycles, depth, keys -------------------------------------------------------------

@pytest.mark.parametrize("make", [
    "v = []; v.append(v)",
    "v = {}; v['a'] = v",
    "v = [1, {'x': None}]; v[1]['x'] = (v,)",
    "v = functools.reduce(lambda a, _: [a], range(100000), [])",
])
def test_recursive_or_deep_override_is_value_error(tmp_path, make):
    out = tmp_path / "out"
    code, text = _child(f"""
        import functools, flexbench
        {make}
        for call in (
                lambda: flexbench.run_scenario({SMOKE!r}, {str(out)!r}, overrides={{"foo": v}}),
                lambda: flexbench.make_estimator(
                    "ppoe_ekf", flexbench.DeclaredModel.load({DECLARED!r}), covariance_order=v)):
            try:
                call()
                print("no error")
            except ValueError as e:
                print("ValueError:", e)
        """)
    assert code == 0, text
    lines = [l for l in text.splitlines() if l.startswith("ValueError:")]
    assert len(lines) == 2, text
    assert "overrides['foo']" in lines[0] and "parameter 'covariance_order'" in lines[1], text
    for line in lines:
        assert "contains itself" in line or "nested deeper than 64 levels" in line, text
    assert _leftovers(out) == []


def test_override_nested_just_under_the_cap_is_converted(tmp_path):
    # Depth is capped, not forbidden: 60 levels reach the scenario parser, which names the key.
    v = 1
    for _ in range(60):
        v = [v]
    with pytest.raises(ValueError, match="render.mode"):
        flexbench.run_scenario(SMOKE, str(tmp_path / "o"), overrides={"render.mode": v})


@pytest.mark.parametrize("key", ["seed=7 #", "detector.threads: 2, seed", "a,b", "a..b", ".a",
                                 "a.", "", "render mode", "seed\n", "détecteur"])
def test_override_key_that_is_not_a_dotted_name_is_refused(tmp_path, key):
    out = tmp_path / "o"
    with pytest.raises(ValueError, match="is not a dotted name"):
        flexbench.run_scenario(SMOKE, str(out), seed=1, overrides={key: 1})
    if "=" not in key:  # in a list the first '=' ends the key
        with pytest.raises(ValueError, match="is not a dotted name"):
            flexbench.run_scenario(SMOKE, str(out), seed=1, overrides=[f"{key}=1"])
    assert not out.exists()


def test_override_key_must_be_a_str(tmp_path):
    with pytest.raises(ValueError, match="a key must be a str, got int"):
        flexbench.run_scenario(SMOKE, str(tmp_path / "o"), overrides={1: 2})


def test_nested_dict_keys_and_strings_stay_inside_their_value(tmp_path):
    # Built as YAML text without quoting, this key set joint1 = 0.1 and joint2 = 0.5 (and a
    # str in a list could add list items): each is one key, one string, however it is spelled.
    out = tmp_path / "o"
    with pytest.raises(ValueError, match=r"joint1: 0\.1, joint2"):
        flexbench.run_scenario(SMOKE, str(out),
                               overrides={"configuration": {"joint1: 0.1, joint2": 0.5}})
    assert not out.exists()
    with pytest.raises(ValueError) as e:
        flexbench.make_estimator("ppoe_ekf", flexbench.DeclaredModel.load(DECLARED),
                                 covariance_order=["2, 4"])
    assert "2, 4" in str(e.value)


def test_estimator_and_parameter_names_are_plain_names():
    model = flexbench.DeclaredModel.load(DECLARED)
    with pytest.raises(ValueError, match="estimator name 'ppoe_ekf.x'"):
        flexbench.make_estimator("ppoe_ekf.x", model)
    with pytest.raises(ValueError, match="parameter 'covariance_order: 4, x'"):
        flexbench.make_estimator("ppoe_ekf", model, **{"covariance_order: 4, x": 1})


# ---- MuJoCo's fatal errors ------------------------------------------------------------------

def _model_with(tmp_path, old, new, name="m.xml"):
    xml = (SOURCE / "models" / "planar3.xml").read_text()
    assert old in xml
    path = tmp_path / name
    path.write_text(xml.replace(old, new))
    return path


def _smoke_with_model(tmp_path, model, name="s.yaml"):
    text = (SOURCE / "scenarios" / "smoke.yaml").read_text()
    path = tmp_path / name
    path.write_text(text.replace("model: ../models/planar3.xml", f"model: {model}"))
    return path


def test_shadowsize_too_big_is_value_error_and_python_lives_on(tmp_path):
    # It used to end the interpreter with exit code 2 from MuJoCo's error handler and leave
    # OUT.tmp-PID behind.
    model = _model_with(tmp_path, 'shadowsize="2048"', 'shadowsize="60000"')
    bad = _smoke_with_model(tmp_path, model)
    out = tmp_path / "out"
    code, text = _child(f"""
        import flexbench
        try:
            flexbench.run_scenario({str(bad)!r}, {str(out)!r})
            print("no error")
        except ValueError as e:
            print("ValueError:", e)
        s = flexbench.run_scenario({SMOKE!r}, {str(out) + "_ok"!r}, seed=2)
        print("then:", all(g["passed"] for g in s["gates"]))
        """)
    assert code == 0, text
    assert f"ValueError: {model}: <visual><quality shadowsize=\"60000\">" in text, text
    assert "then: True" in text, text
    assert _leftovers(out) == [str(out) + "_ok"]


def test_mujoco_error_mid_run_is_value_error_and_the_next_run_works(tmp_path):
    # A model that loads, with MuJoCo's stack just big enough to compile it; the configuration
    # swings a pendulum into the floor and the contacts overflow the stack in the run, after the
    # output temporary exists. It used to end the interpreter (exit code 2) and leave the
    # temporary behind.
    xml = (SOURCE / "models" / "planar3.xml").read_text()
    xml = xml.replace("  </worldbody>", """    <body name="pendulum" pos="-0.5 0 0.2">
      <joint name="swing" type="hinge" axis="1 0 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.4" size="0.03"/>
    </body>
  </worldbody>""").replace("<option", '<size nstack="120"/>\n  <option', 1)
    model = tmp_path / "pendulum.xml"
    model.write_text(xml)
    scenario = _smoke_with_model(tmp_path, model)
    scenario.write_text(scenario.read_text().replace("  joint3: 0.5", "  joint3: 0.5\n  swing: 2.5"))
    out = tmp_path / "out"
    code, text = _child(f"""
        import flexbench
        for attempt in range(2):
            try:
                flexbench.run_scenario({str(scenario)!r}, {str(out)!r})
                print("no error")
            except ValueError as e:
                print("ValueError:", e)
        s = flexbench.run_scenario({SMOKE!r}, {str(out) + "_ok"!r}, seed=2)
        print("then:", all(g["passed"] for g in s["gates"]))
        """)
    assert code == 0, text
    assert text.count("ValueError: MuJoCo: Stack overflow") == 2, text
    assert "then: True" in text, text
    assert _leftovers(out) == [str(out) + "_ok"]


def test_bad_visual_sizes_name_the_file_and_attribute(tmp_path):
    for k, (old, new, attribute) in enumerate([
            ('shadowsize="2048"', 'shadowsize="-1"', "shadowsize"),
            ('offwidth="640"', 'offwidth="60000"', "offwidth"),
            ('shadowsize="2048"', 'shadowsize="2048" offsamples="99"', "offsamples")]):
        model = _model_with(tmp_path, old, new, f"m{k}.xml")
        scenario = _smoke_with_model(tmp_path, model, f"s{k}.yaml")
        out = tmp_path / f"o{k}"
        code, text = _child(f"""
            import flexbench
            try:
                flexbench.run_scenario({str(scenario)!r}, {str(out)!r})
                print("no error")
            except ValueError as e:
                print("ValueError:", e)
            """)
        assert code == 0, text
        assert f"ValueError: {model}: <visual>" in text and attribute in text, text
        assert _leftovers(out) == []


# ---- threads ----------------------------------------------------------------------------------

def test_run_scenario_from_four_threads(tmp_path):
    # Concurrent runs used to end the process ("Shadow framebuffer is not complete") or crash:
    # calls are serialised, and each returns its own run's summary.
    code, text = _child(f"""
        import threading, flexbench
        results, errors = {{}}, []
        def work(i):
            try:
                if i % 2:
                    flexbench.DeclaredModel.load({DECLARED!r})
                s = flexbench.run_scenario({SMOKE!r}, {str(tmp_path)!r} + f"/out{{i}}", seed=i + 1)
                results[i] = (s["seed"], all(g["passed"] for g in s["gates"]))
            except Exception as e:
                errors.append(repr(e))
        threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
        for t in threads: t.start()
        for t in threads: t.join()
        print("errors:", errors)
        print("results:", sorted(results.items()))
        """)
    assert code == 0, text
    assert "errors: []" in text, text
    assert "results: [(0, (1, True)), (1, (2, True)), (2, (3, True)), (3, (4, True))]" in text, text
    for i in range(4):
        assert (tmp_path / f"out{i}" / "summary.json").is_file()


def test_other_threads_run_python_while_a_run_waits_or_works(tmp_path):
    # The lock is waited for without the GIL: a pure-Python thread keeps counting meanwhile.
    code, text = _child(f"""
        import threading, time, flexbench
        stop = False
        count = [0]
        def spin():
            while not stop:
                count[0] += 1
        t = threading.Thread(target=spin); t.start()
        runs = [threading.Thread(target=flexbench.run_scenario,
                                 args=({SMOKE!r}, {str(tmp_path)!r} + f"/o{{i}}"))
                for i in range(2)]
        for r in runs: r.start()
        before = count[0]
        for r in runs: r.join()
        stop = True; t.join()
        print("counted:", count[0] - before > 1000)
        """)
    assert code == 0, text
    assert "counted: True" in text, text


# ---- estimator updates: noise and time --------------------------------------------------------

@pytest.fixture(scope="module")
def model():
    return flexbench.DeclaredModel.load(DECLARED)


@pytest.mark.parametrize("name", ["ppoe_ekf", "fk", "pf_encoders"])
@pytest.mark.parametrize("t, std", [(0.0, -1.0), (0.0, 0.0), (0.0, math.nan), (0.0, math.inf),
                                    (math.nan, 1e-3), (math.inf, 1e-3), (0.0, -1),
                                    (0.0, [1e-3] * 7 + [0.0]), (0.0, [1e-3] * 7 + [math.nan])])
def test_update_joints_refuses_bad_noise_and_time(model, name, t, std):
    est = flexbench.make_estimator(name, model, seed=1)
    q = np.radians([10.0, -30.0, 45.0, 0.0, 20.0, 5.0, 0.0, -10.0])
    assert est.update_joints(0.0, q, 1e-3) == "accepted"
    before = est.belief()
    with pytest.raises(ValueError, match=r"^(t: expected a finite time|std(\[7\])?: expected a "
                                         r"finite noise std > 0)"):
        est.update_joints(t, q, std)
    after = est.belief()
    assert after["t"] == before["t"]
    assert np.array_equal(after["q_std"], before["q_std"])
    assert np.all(np.isfinite(after["q_std"])) and np.all(np.isfinite(after["cov"]))


def test_update_joints_needs_a_std(model):
    est = flexbench.make_estimator("ppoe_ekf", model)
    with pytest.raises(TypeError):
        est.update_joints(0.0, np.zeros(8))


def test_every_update_refuses_a_time_that_is_not_finite(model):
    est = flexbench.make_estimator("ppoe_ekf", model, camera_frames=["mast_camera"],
                                   imu_frames=["ee"])
    z3 = np.zeros(3)
    calls = [
        lambda t: est.predict(t),
        lambda t: est.update_imu(t, z3, z3),
        lambda t: est.update_orientation(t, "ee", [1.0, 0.0, 0.0, 0.0]),
        lambda t: est.update_pixel(t, "ee", z3, [320.0, 240.0]),
        lambda t: est.update_tag(t, "ee", np.zeros((4, 3)), np.full((4, 2), 100.0)),
        lambda t: est.update_contact(t, "ee", z3, np.eye(4)),
        lambda t: est.update_position(t, "ee", z3, z3),
        lambda t: est.update_pose(t, "ee", np.eye(4)),
    ]
    for call in calls:
        for t in (math.nan, math.inf, -math.inf):
            with pytest.raises(ValueError, match="^t: expected a finite time"):
                call(t)


def _spd_violations(n):
    bad_sym = np.eye(n)
    bad_sym[0, 1] = 0.5
    neg = np.eye(n)
    neg[0, 0] = -1.0
    nan = np.eye(n)
    nan[0, 0] = math.nan
    return [(-np.eye(n), "not positive definite"), (np.zeros((n, n)), "not positive definite"),
            (neg, "not positive definite"), (bad_sym, "not symmetric"), (nan, "not finite"),
            (np.full((n, n), math.inf), "not finite")]


def test_every_covariance_must_be_a_covariance(model):
    est = flexbench.make_estimator("ppoe_ekf", model, camera_frames=["mast_camera"])
    q = np.radians([10.0, -30.0, 45.0, 0.0, 20.0, 5.0, 0.0, -10.0])
    assert est.update_joints(0.0, q, 1e-3) == "accepted"
    before = est.estimate()
    z3 = np.zeros(3)
    calls = {
        2: lambda c: est.update_pixel(0.0, "ee", z3, [320.0, 240.0], c),
        8: lambda c: est.update_tag(0.0, "ee", np.zeros((4, 3)), np.full((4, 2), 100.0), c),
        3: lambda c: est.update_position(0.0, "ee", z3, z3, c),
        6: lambda c: est.update_pose(0.0, "ee", np.eye(4), c),
    }
    for n, call in calls.items():
        for cov, message in _spd_violations(n):
            with pytest.raises(ValueError, match=f"^cov: {message}"):
                call(cov)
    # A plane known exactly is a zero covariance; a negative or NaN one is refused, and so is a
    # std that is not > 0.
    assert isinstance(est.update_contact(0.0, "ee", z3, np.eye(4), np.zeros((6, 6)), 0.0, 1e-3),
                      str)
    with pytest.raises(ValueError, match="^plane_cov: not positive semi-definite"):
        est.update_contact(0.0, "ee", z3, np.eye(4), -np.eye(6), 0.0, 1e-3)
    with pytest.raises(ValueError, match="^plane_cov: not finite"):
        est.update_contact(0.0, "ee", z3, np.eye(4), np.full((6, 6), math.nan), 0.0, 1e-3)
    for std in (0.0, -1e-3, math.nan, math.inf):
        with pytest.raises(ValueError, match="^std: expected a finite noise std > 0"):
            est.update_contact(0.0, "ee", z3, np.eye(4), None, 0.0, std)
    T, cov = est.estimate()
    assert np.all(np.isfinite(cov)) and np.all(np.isfinite(T))


def test_readings_that_are_not_finite_are_rejected_not_raised(model):
    # A reading's own values are the sensor's: NaN is 'rejected_non_finite' and leaves the
    # belief as it was (tests/python/test_module.py says the same for joints).
    est = flexbench.make_estimator("ppoe_ekf", model)
    q = np.radians([10.0, -30.0, 45.0, 0.0, 20.0, 5.0, 0.0, -10.0])
    assert est.update_joints(0.0, q, 1e-3) == "accepted"
    T0, cov0 = est.estimate()
    assert est.update_position(0.0, "ee", np.zeros(3), np.full(3, math.nan)) == \
        "rejected_non_finite"
    T1, cov1 = est.estimate()
    assert np.array_equal(T0, T1) and np.array_equal(cov0, cov1)


def test_an_override_longer_than_the_file_cap_is_refused_unparsed(tmp_path):
    # A 300 MB "KEY=VALUE" string once took 31 s and 2 GB in the YAML parser.
    value = "configuration.joint1=" + "1" * (17 << 20)
    with pytest.raises(ValueError) as e:
        flexbench.run_scenario(SMOKE, str(tmp_path / "o"), overrides=[value])
    assert "more than the 16777216 an override may hold" in str(e.value)
    assert not (tmp_path / "o").exists()
