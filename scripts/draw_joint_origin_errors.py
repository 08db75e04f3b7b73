#!/usr/bin/env python3
"""Draws the truth errors of scenarios/closed_loop_humanoid_dlr.yaml once, with a fixed seed.

Per read joint of models/humanoid_upper_torso.declared.yaml: a joint-origin error whose
translation has a length uniform in [0.5, 2] mm and whose rotation an angle uniform in
[0.1, 0.5] deg, each along a direction uniform on the sphere; per hand marker, where it really
sits: an offset of length uniform in [2, 5] mm from the declared site. Prints the YAML blocks the
scenario holds (pasted there as printed). Usage: scripts/draw_joint_origin_errors.py [seed]
"""
import math
import random
import sys

JOINTS = ["torso_yaw", "torso_pitch_1", "torso_pitch_2",
          "shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow", "forearm_roll",
          "wrist_pitch", "wrist_yaw",
          "l_shoulder_pitch", "l_shoulder_roll", "l_shoulder_yaw", "l_elbow", "l_forearm_roll",
          "l_wrist_pitch", "l_wrist_yaw"]
MARKERS = ["right_marker", "left_marker"]


def direction(rng):
    """A unit vector uniform on the sphere (normalised Gaussian)."""
    while True:
        v = [rng.gauss(0.0, 1.0) for _ in range(3)]
        n = math.sqrt(sum(x * x for x in v))
        if n > 1e-9:
            return [x / n for x in v]


def vector(rng, low, high):
    length = rng.uniform(low, high)
    return [round(length * x, 3) for x in direction(rng)]


def main():
    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 34
    rng = random.Random(seed)
    print(f"    # drawn by scripts/draw_joint_origin_errors.py {seed}")
    print("    joint_origin:")
    print("      errors:")
    for j in JOINTS:
        pos = vector(rng, 0.5, 2.0)
        rot = vector(rng, 0.1, 0.5)
        print(f"        {j}: {{pos_mm: {pos}, rot_deg: {rot}}}")
    print("    marker_offsets_mm:")
    for m in MARKERS:
        print(f"      {m}: {vector(rng, 2.0, 5.0)}")


if __name__ == "__main__":
    main()
