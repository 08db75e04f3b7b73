#!/usr/bin/env python3
"""Python overhead of DeclaredModel.fk_cov (numpy in, numpy out) against the same C++ call.

Both are timed in the same process, interleaved, on the rover arm's declared model (8 joint
variables, 9 sources): the C++ side is ForwardKinematicsWithCovariance looped in C++
(flexbench._bench_fk_cov), the Python side is `model.fk_cov(q, frame)` timed with timeit.
Prints the median per-call time of each over several repeats and their difference. Both sides
use the same clock: the process's CPU time by default (on a shared machine other processes'
load then inflates neither), or wall time with --clock wall.

  PYTHONPATH=build/python /usr/bin/python3 scripts/bench_python.py [--repeats 15] [--check 3.0]

--check US exits 1 when the median added overhead exceeds US microseconds.
"""
import argparse
import statistics
import sys
import time
import timeit
from pathlib import Path

import numpy as np

import flexbench

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--declared", default=str(ROOT / "models" / "rover_arm.declared.yaml"))
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--calls", type=int, default=20000, help="calls per repeat")
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--check", type=float, default=None, metavar="US")
    ap.add_argument("--clock", choices=["cpu", "wall"], default="cpu")
    args = ap.parse_args()
    timer = time.process_time if args.clock == "cpu" else time.perf_counter

    model = flexbench.DeclaredModel.load(args.declared)
    q = np.linspace(-0.6, 0.7, model.nq)
    ee = model.frame_id("ee")
    fk_cov = model.fk_cov
    order = args.order

    cases = {
        "python fk_cov(q, 'ee')": lambda: fk_cov(q, "ee", order=order),
        "python fk_cov(q, ee_id)": lambda: fk_cov(q, ee, order=order),
    }
    n = args.calls
    cpp, py = [], {k: [] for k in cases}
    bench = flexbench._bench_fk_cov

    def cpp_loop():
        t0 = timer()
        bench(model, q, n, order)  # n calls looped in C++
        return timer() - t0

    cpp_loop()  # warm up
    for f in cases.values():
        timeit.timeit(f, number=n // 10, timer=timer)
    for _ in range(args.repeats):
        cpp.append(cpp_loop() / n)
        for k, f in cases.items():
            py[k].append(timeit.timeit(f, number=n, timer=timer) / n)

    c = statistics.median(cpp)
    print(f"model {args.declared} nq={model.nq} ({len(model.frame_names)} frames), order {order}, "
          f"{args.repeats} repeats x {n} calls, {args.clock} time, medians per call:")
    print(f"  C++ ForwardKinematicsWithCovariance: {c * 1e6:8.3f} us")
    worst = 0.0
    for k, v in py.items():
        m = statistics.median(v)
        worst = max(worst, m - c)
        print(f"  {k:34s} {m * 1e6:8.3f} us   overhead {(m - c) * 1e6:+.3f} us")
    if args.check is not None and worst * 1e6 > args.check:
        print(f"FAIL: overhead {worst * 1e6:.3f} us > {args.check} us", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
