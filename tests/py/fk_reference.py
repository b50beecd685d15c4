"""Independent forward-kinematics reference for tests/tests/fk_reference.rs.

Reads JSON {"model": "fr3" | "panda" | "ur5" | "ur5e", "frame": "flange" | "tcp",
"q": [[q1, ...], ...]} from stdin ("frame" defaults to "flange") and prints, per joint vector,
[[x, y, z, roll, pitch, yaw], [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]]]: the pose of
the frame in the arm's base frame and its rotation matrix, computed straight from the DH tables
of REFERENCE §8 with ROS rpy (R = Rz(yaw)·Ry(pitch)·Rx(roll)). "tcp" is the Franka Hand TCP
(flange + 0.1034 m along z, −π/4 about z) for fr3/panda and tool0 (the flange) for ur5/ur5e,
as the README defines the converter's pose. Uses numpy only, no project code.
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

# Franka Hand TCP in the flange frame: 0.1034 m along z, then −π/4 about z.
FRANKA_HAND_Z = 0.1034
FRANKA_HAND_YAW = -np.pi / 4

# UR5 and UR5e, standard DH (d, a, alpha).
UR5_DH = [
    (0.089159, 0.0, HALF_PI),
    (0.0, -0.425, 0.0),
    (0.0, -0.39225, 0.0),
    (0.10915, 0.0, HALF_PI),
    (0.09465, 0.0, -HALF_PI),
    (0.0823, 0.0, 0.0),
]
UR5E_DH = [
    (0.1625, 0.0, HALF_PI),
    (0.0, -0.425, 0.0),
    (0.0, -0.3922, 0.0),
    (0.1333, 0.0, HALF_PI),
    (0.0997, 0.0, -HALF_PI),
    (0.0996, 0.0, 0.0),
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


def franka_hand():
    """TransZ(0.1034)·RotZ(−π/4), written out."""
    c, s = np.cos(FRANKA_HAND_YAW), np.sin(FRANKA_HAND_YAW)
    return np.array(
        [
            [c, -s, 0.0, 0.0],
            [s, c, 0.0, 0.0],
            [0.0, 0.0, 1.0, FRANKA_HAND_Z],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def flange(model, q):
    t = np.eye(4)
    if model in ("fr3", "panda"):
        if len(q) != 7:
            raise ValueError(f"{model} needs 7 joint positions, got {len(q)}")
        for (a, d, alpha), theta in zip(FRANKA_MDH, list(q) + [0.0]):
            t = t @ modified_dh(a, d, alpha, theta)
    elif model in ("ur5", "ur5e"):
        if len(q) != 6:
            raise ValueError(f"{model} needs 6 joint positions, got {len(q)}")
        for (d, a, alpha), theta in zip(UR5_DH if model == "ur5" else UR5E_DH, q):
            t = t @ standard_dh(d, a, alpha, theta)
    else:
        raise ValueError(f"unknown model {model!r}")
    return t


def tcp(model, q):
    t = flange(model, q)
    return t @ franka_hand() if model in ("fr3", "panda") else t


def rpy(r):
    """Roll, pitch, yaw with R = Rz(yaw)·Ry(pitch)·Rx(roll) (pitch by atan2, not asin).

    Roll and yaw are meaningless at gimbal lock (|r20| = 1); the caller compares rotation
    matrices there.
    """
    pitch = np.arctan2(-r[2, 0], np.hypot(r[0, 0], r[1, 0]))
    roll = np.arctan2(r[2, 1], r[2, 2])
    yaw = np.arctan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


def main():
    req = json.load(sys.stdin)
    frame = req.get("frame", "flange")
    if frame not in ("flange", "tcp"):
        raise ValueError(f"unknown frame {frame!r}")
    out = []
    for q in req["q"]:
        t = flange(req["model"], q) if frame == "flange" else tcp(req["model"], q)
        r = t[:3, :3]
        pose = [float(v) for v in (*t[:3, 3], *rpy(r))]
        out.append([pose, [[float(v) for v in row] for row in r]])
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
