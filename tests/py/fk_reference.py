"""Independent forward-kinematics reference for tests/tests/fk_reference.rs.

Reads JSON {"model": "fr3" | "ur5", "q": [[q1, ...], ...]} from stdin and prints the flange
poses [[x, y, z, roll, pitch, yaw], ...] computed straight from the DH tables of REFERENCE §8,
with ROS rpy (R = Rz(yaw)·Ry(pitch)·Rx(roll)). Uses numpy only, no project code.
"""

import json
import sys

import numpy as np

HALF_PI = np.pi / 2

# Franka FR3/Panda, modified DH (a, d, alpha); the last row is the flange (theta = 0).
FRANKA_MDH = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -HALF_PI),
    (0.0, 0.316, HALF_PI),
    (0.0825, 0.0, HALF_PI),
    (-0.0825, 0.384, -HALF_PI),
    (0.0, 0.0, HALF_PI),
    (0.088, 0.0, HALF_PI),
    (0.0, 0.107, 0.0),
]

# UR5, standard DH (d, a, alpha).
UR5_DH = [
    (0.089159, 0.0, HALF_PI),
    (0.0, -0.425, 0.0),
    (0.0, -0.39225, 0.0),
    (0.10915, 0.0, HALF_PI),
    (0.09465, 0.0, -HALF_PI),
    (0.0823, 0.0, 0.0),
]


def modified_dh(a, d, alpha, theta):
    """RotX(alpha)·TransX(a)·RotZ(theta)·TransZ(d), written out (Craig's form)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -d * sa],
            [st * sa, ct * sa, ca, d * ca],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def standard_dh(d, a, alpha, theta):
    """RotZ(theta)·TransZ(d)·TransX(a)·RotX(alpha), written out."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def flange(model, q):
    t = np.eye(4)
    if model == "fr3":
        if len(q) != 7:
            raise ValueError(f"fr3 needs 7 joint positions, got {len(q)}")
        for (a, d, alpha), theta in zip(FRANKA_MDH, list(q) + [0.0]):
            t = t @ modified_dh(a, d, alpha, theta)
    elif model == "ur5":
        if len(q) != 6:
            raise ValueError(f"ur5 needs 6 joint positions, got {len(q)}")
        for (d, a, alpha), theta in zip(UR5_DH, q):
            t = t @ standard_dh(d, a, alpha, theta)
    else:
        raise ValueError(f"unknown model {model!r}")
    return t


def rpy(r):
    """Roll, pitch, yaw with R = Rz(yaw)·Ry(pitch)·Rx(roll) (pitch by atan2, not asin)."""
    pitch = np.arctan2(-r[2, 0], np.hypot(r[0, 0], r[1, 0]))
    roll = np.arctan2(r[2, 1], r[2, 2])
    yaw = np.arctan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


def main():
    req = json.load(sys.stdin)
    out = []
    for q in req["q"]:
        t = flange(req["model"], q)
        out.append([float(v) for v in (*t[:3, 3], *rpy(t[:3, :3]))])
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
