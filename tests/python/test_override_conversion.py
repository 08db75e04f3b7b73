"""What the override conversion (scenarios/python/overrides.cc) refuses, found by its fuzzer
(tests/fuzz/fuzz_python_overrides.cc): every refusal is a ValueError naming the override, and
nothing is run. Run by ctest with the rest of tests/python (PYTHONPATH=build/python).
"""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import flexbench

SOURCE = Path(os.environ.get("FLEXBENCH_SOURCE_DIR", Path(__file__).resolve().parents[2]))
SMOKE = str(SOURCE / "scenarios" / "smoke.yaml")
DECLARED = str(SOURCE / "models" / "rover_arm.declared.yaml")

# A lone surrogate: what os.fsdecode makes of a byte that is not UTF-8 (b"\xff").
LONE = "\udcff"


@pytest.mark.parametrize("overrides, named", [
    ({"render.mode": LONE}, "overrides['render.mode']"),
    ({"render.mode": [LONE]}, "overrides['render.mode']"),
    ({"configuration": {LONE: 0.1}}, "overrides['configuration'] (a key)"),
    ({LONE: 1}, "overrides: a key"),
    ([f"render.mode={LONE}"], "overrides: an item"),
])
def test_str_with_a_lone_surrogate_is_value_error(tmp_path, overrides, named):
    out = tmp_path / "o"
    with pytest.raises(ValueError, match="lone surrogate") as e:
        flexbench.run_scenario(SMOKE, str(out), overrides=overrides)
    assert named in str(e.value)
    assert not out.exists()


def test_parameter_with_a_lone_surrogate_is_value_error():
    model = flexbench.DeclaredModel.load(DECLARED)
    with pytest.raises(ValueError, match=r"parameter 'covariance_order'.*lone surrogate"):
        flexbench.make_estimator("ppoe_ekf", model, covariance_order=[LONE])


@pytest.mark.parametrize("overrides", [5, 2.5, True, object()])
def test_overrides_that_cannot_be_iterated_are_value_error(tmp_path, overrides):
    out = tmp_path / "o"
    with pytest.raises(ValueError, match="expected a dict or a list of 'KEY=VALUE' strings, got"):
        flexbench.run_scenario(SMOKE, str(out), overrides=overrides)
    assert not out.exists()


@pytest.mark.parametrize("make, message", [
    # [v, v] of [v, v] ...: 2**40 values from 41 objects.
    ("v = functools.reduce(lambda a, _: [a, a], range(40), 0)", "more than 1000000 values"),
    # One 1 MiB str, 100 times: 100 MiB of YAML text.
    ("v = ['x' * (1 << 20)] * 100", "more than 16 MiB as YAML text"),
])
def test_value_that_repeats_an_object_is_capped(tmp_path, make, message):
    # In a child with 2 GB of address space: before the cap, the conversion ran for hours or
    # until memory ran out.
    code = textwrap.dedent(f"""
        import functools, resource, flexbench
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
        {make}
        for call in (
                lambda: flexbench.run_scenario({SMOKE!r}, {str(tmp_path / 'o')!r},
                                               overrides={{"configuration": v}}),
                lambda: flexbench.make_estimator(
                    "ppoe_ekf", flexbench.DeclaredModel.load({DECLARED!r}), covariance_order=v)):
            try:
                call()
                print("no error")
            except ValueError as e:
                print("ValueError:", e)
        """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=env, cwd=SOURCE)
    lines = [l for l in p.stdout.splitlines() if l.startswith("ValueError:")]
    assert p.returncode == 0 and len(lines) == 2, p.stdout + p.stderr
    assert "overrides['configuration']" in lines[0] and message in lines[0], lines
    assert "parameter 'covariance_order'" in lines[1] and message in lines[1], lines


def test_parameter_name_with_a_lone_surrogate_is_value_error():
    model = flexbench.DeclaredModel.load(DECLARED)
    with pytest.raises(ValueError, match="a parameter name: .*lone surrogate"):
        flexbench.make_estimator("ppoe_ekf", model, **{LONE: 1})


def test_int_too_long_to_write_names_the_override(tmp_path):
    with pytest.raises(ValueError, match=r"overrides\['seed'\]: an int with more digits"):
        flexbench.run_scenario(SMOKE, str(tmp_path / "o"), overrides={"seed": 10**5000})
