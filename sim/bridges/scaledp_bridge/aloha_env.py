"""gym-aloha's bimanual tasks (transfer-cube, insertion) as a robot the stack can drive.

- Two ViperX 300 arms (6 joints each) and their grippers, the ``top`` camera; one step is
  20 ms (50 Hz, 10 physics steps of 2 ms); an episode is 400 steps (the ACT paper's length;
  insertion's expert needs up to ~390). Success is the task's full reward (4).
- Commands are joint targets per arm (what a leader arm publishes) and a gripper opening; the
  opening maps linearly to gym-aloha's normalized gripper action (0 closed, 1 open) over the
  fingers' travel (each finger 0.01844 ... 0.05800 m, so an opening of 0.0369 ... 0.116 m).
- The scripted expert is the ACT paper's (its facts, written here): waypoints of both grippers
  in end-effector space, followed on the mocap-driven variant of the task with the seed's
  object poses, then the recorded joint trajectory (grippers as the commanded openings)
  replayed in the joint-controlled task from the same poses.
- Under MuJoCo 3 that expert fails unless the mocap weld's torque scale is raised
  (``eq_data[:, 10] = 30``) and multi-CCD is disabled; both physics settings apply to both
  variants, in collection and evaluation alike.
- Seeds: ``reset(seed)`` draws the cube (or the peg and socket) from that seed, as gym-aloha's
  own ``reset(seed)`` does, for both variants.
"""

from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from .cameras import set_up
from .protocol import Reply

#: Each finger's travel (gym-aloha's PUPPET_GRIPPER_POSITION_CLOSE / OPEN).
FINGER_CLOSED_M = 0.01844
FINGER_OPEN_M = 0.05800
STEPS = 400
#: The bridge's behaviour: raised whenever a change to this file can change an episode's
#: outcome, reported in ``hello``'s versions as ``scaledp-bridge`` and recorded with every
#: evaluation (``experiment compare --rescore`` scores a result of an earlier one again).
#: 1: every result so far (``reset`` has always restored the held targets).
BEHAVIOUR = "1"
ARM_JOINTS = ["waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate"]
TASKS = {"transfer-cube": "transfer_cube", "insertion": "insertion"}
#: What each of gym-aloha's rewards 1-4 means (its ``get_reward``), the stages ACT's evaluation
#: counts episodes by (highest reward >= r): the cube touched by the right gripper, lifted off
#: the table, touched by the left gripper, held by it off the table; both grippers touching
#: peg and socket, both lifted, the peg touching the socket in the air, the pin touched.
STAGES = {"transfer_cube": ["touched", "lifted", "transfer attempted", "transferred"],
          "insertion": ["both touched", "both grasped", "peg meets socket", "inserted"]}


def width_of(normalized: float) -> float:
    """The fingers' opening (m) of a normalized gripper value (0 closed, 1 open)."""
    return 2.0 * (FINGER_CLOSED_M + normalized * (FINGER_OPEN_M - FINGER_CLOSED_M))


def normalized_of(width_m: float) -> float:
    """The normalized gripper value of an opening (m)."""
    return (width_m / 2.0 - FINGER_CLOSED_M) / (FINGER_OPEN_M - FINGER_CLOSED_M)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _axis_quat(axis: Sequence[float], degrees: float) -> np.ndarray:
    half = np.deg2rad(degrees) / 2.0
    return np.concatenate([[np.cos(half)], np.sin(half) * np.asarray(axis, dtype=np.float64)])


def _waypoints(task: str, left0: np.ndarray, right0: np.ndarray, objects: np.ndarray):
    """The ACT paper's gripper waypoints: (step, xyz, quat, gripper) per arm."""
    quat_r = _quat_mul(right0[3:], _axis_quat([0, 1, 0], -60))
    if task == "transfer_cube":
        box = objects[:3]
        meet = np.array([0.0, 0.5, 0.25])
        meet_q = _axis_quat([1, 0, 0], 90)
        ident = np.array([1.0, 0, 0, 0])
        left = [(0, left0[:3], left0[3:], 0), (100, meet + [-0.1, 0, -0.02], meet_q, 1),
                (260, meet + [0.02, 0, -0.02], meet_q, 1), (310, meet + [0.02, 0, -0.02], meet_q, 0),
                (360, meet + [-0.1, 0, -0.02], ident, 0), (400, meet + [-0.1, 0, -0.02], ident, 0)]
        right = [(0, right0[:3], right0[3:], 0), (90, box + [0, 0, 0.08], quat_r, 1),
                 (130, box + [0, 0, -0.015], quat_r, 1), (170, box + [0, 0, -0.015], quat_r, 0),
                 (200, meet + [0.05, 0, 0], quat_r, 0), (220, meet, quat_r, 0),
                 (310, meet, quat_r, 1), (360, meet + [0.1, 0, 0], quat_r, 1),
                 (400, meet + [0.1, 0, 0], quat_r, 1)]
        return left, right
    peg, socket = objects[:3], objects[7:10]
    quat_l = _quat_mul(right0[3:], _axis_quat([0, 1, 0], 60))
    meet = np.array([0.0, 0.5, 0.15])
    lift = 0.00715
    left = [(0, left0[:3], left0[3:], 0), (120, socket + [0, 0, 0.08], quat_l, 1),
            (170, socket + [0, 0, -0.03], quat_l, 1), (220, socket + [0, 0, -0.03], quat_l, 0),
            (285, meet + [-0.1, 0, 0], quat_l, 0), (340, meet + [-0.05, 0, 0], quat_l, 0),
            (400, meet + [-0.05, 0, 0], quat_l, 0)]
    right = [(0, right0[:3], right0[3:], 0), (120, peg + [0, 0, 0.08], quat_r, 1),
             (170, peg + [0, 0, -0.03], quat_r, 1), (220, peg + [0, 0, -0.03], quat_r, 0),
             (285, meet + [0.1, 0, lift], quat_r, 0), (340, meet + [0.05, 0, lift], quat_r, 0),
             (400, meet + [0.05, 0, lift], quat_r, 0)]
    return left, right


def _at(waypoints, t: int) -> np.ndarray:
    """The linear interpolation of a waypoint list at step t: xyz, quat (not renormalized, as
    ACT's expert), gripper."""
    for (t0, x0, q0, g0), (t1, x1, q1, g1) in zip(waypoints, waypoints[1:]):
        if t0 <= t <= t1:
            f = (t - t0) / (t1 - t0)
            x0, x1, q0, q1 = (np.asarray(v, dtype=np.float64) for v in (x0, x1, q0, q1))
            return np.concatenate([x0 + (x1 - x0) * f, q0 + (q1 - q0) * f, [g0 + (g1 - g0) * f]])
    _, x, q, g = waypoints[-1]
    return np.concatenate([np.asarray(x, float), np.asarray(q, float), [g]])


class _Blind:
    """gym-aloha's tasks render three 480x640 cameras into every observation (most of a step's
    time); the bridge renders its own cameras at the rig's size, so the tasks' observations
    carry the state alone (what the expert and the reward read)."""

    def get_observation(self, physics):
        obs = {"qpos": self.get_qpos(physics), "gripper_ctrl": physics.data.ctrl.copy()}
        if physics.model.nmocap:
            obs["mocap_pose_left"] = np.concatenate([physics.data.mocap_pos[0], physics.data.mocap_quat[0]])
            obs["mocap_pose_right"] = np.concatenate([physics.data.mocap_pos[1], physics.data.mocap_quat[1]])
        return obs


class AlohaEnv:
    """One gym-aloha task behind the bridge protocol."""

    def __init__(self, task: str, cameras: Sequence[str], width: int, height: int,
                 fovy: Optional[Dict[str, float]] = None):
        os.environ.setdefault("MUJOCO_GL", "egl")
        import gym_aloha
        import mujoco
        from dm_control import mujoco as dm_mujoco
        from dm_control.rl import control
        from gym_aloha.constants import ASSETS_DIR, DT
        from gym_aloha.tasks import sim as joint_tasks
        from gym_aloha.tasks import sim_end_effector as ee_tasks

        if task not in TASKS:
            raise ValueError(f"no ALOHA task {task!r}: one of {', '.join(sorted(TASKS))}")
        self.task = TASKS[task]
        self.mujoco = mujoco
        self.joint_tasks = joint_tasks
        self.ee_tasks = ee_tasks

        def make(xml: str, task_obj):
            physics = dm_mujoco.Physics.from_xml_path(str(ASSETS_DIR / xml))
            m = physics.model.ptr
            # The two physics settings the ACT expert needs under MuJoCo 3.
            if m.neq:
                m.eq_data[:, 10] = 30.0
            m.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_MULTICCD)
            m.vis.quality.shadowsize = 0
            m.vis.quality.offsamples = 0
            return control.Environment(physics, task_obj, float("inf"), control_timestep=DT,
                                       n_sub_steps=None, flat_observation=False)

        seeded = self
        # Per task: the mocap-driven and joint-controlled task classes, the free joint that
        # holds its objects (and how many qpos they take), and the two models.
        base_ee, base_joint, objects_joint, n_qpos = {
            "transfer_cube": (ee_tasks.TransferCubeEndEffectorTask, joint_tasks.TransferCubeTask,
                              "red_box_joint", 7),
            "insertion": (ee_tasks.InsertionEndEffectorTask, joint_tasks.InsertionTask,
                          "red_peg_joint", 14),
        }[self.task]

        class SeededEE(_Blind, base_ee):
            def initialize_episode(self, physics):
                self.initialize_robots(physics)
                i = physics.model.name2id(objects_joint, "joint")
                np.copyto(physics.data.qpos[i:i + n_qpos], seeded.objects)
                base_ee.__mro__[2].initialize_episode(self, physics)

        class Joint(_Blind, base_joint):
            pass

        self.ee = make(f"bimanual_viperx_end_effector_{self.task}.xml", SeededEE())
        self.joint = make(f"bimanual_viperx_{self.task}.xml", Joint())
        self.physics = self.joint.physics
        self.camera_info = set_up(self.physics.model.ptr, cameras, width, height, fovy or {},
                                  "ALOHA")
        self.cameras = list(cameras)
        self.width, self.height = width, height
        self.renderer = mujoco.Renderer(self.physics.model.ptr, height, width)
        self.versions = {"gym-aloha": _version("gym-aloha"), "mujoco": mujoco.__version__,
                         "dm-control": _version("dm_control"), "scaledp-bridge": BEHAVIOUR}
        self.objects = None
        self.plan: List[np.ndarray] = []
        self.step_index = 0
        self.last = None
        self.success = False
        self._gripper = [1.0, 1.0]
        self._target = [np.zeros(6), np.zeros(6)]

    def hello(self) -> Dict[str, Any]:
        arms = [{"joints": [f"vx300s_{side}/{j}" for j in ARM_JOINTS],
                 "gripper_joints": [f"vx300s_{side}/left_finger", f"vx300s_{side}/right_finger"]}
                for side in ("left", "right")]
        return {"env": "aloha", "task": self.task, "step_s": 0.02, "max_steps": STEPS,
                "cameras": self.camera_info,
                "arms": arms, "versions": self.versions, "stages": STAGES[self.task]}

    def _draw(self, seed: int) -> np.ndarray:
        from gym_aloha.utils import sample_box_pose, sample_insertion_pose

        if self.task == "transfer_cube":
            return sample_box_pose(seed)
        return np.concatenate(sample_insertion_pose(seed))

    def _expert_plan(self) -> List[np.ndarray]:
        """The ACT expert's 14-D joint trajectory for the current objects: waypoints followed in
        the mocap-driven variant, its joints recorded, grippers as their commanded openings."""
        from gym_aloha.constants import normalize_puppet_gripper_position

        ts = self.ee.reset()
        left, right = _waypoints(self.task, ts.observation["mocap_pose_left"],
                                 ts.observation["mocap_pose_right"], np.asarray(self.objects))
        plan = []
        for t in range(STEPS):
            plan.append(np.asarray(ts.observation["qpos"], dtype=np.float64).copy())
            ctrl = ts.observation["gripper_ctrl"]
            plan[-1][6] = normalize_puppet_gripper_position(ctrl[0])
            plan[-1][13] = normalize_puppet_gripper_position(ctrl[2])
            ts = self.ee.step(np.concatenate([_at(left, t), _at(right, t)]))
        return plan

    def _images(self, render: bool) -> List[bytes]:
        if not render:
            return []
        out = []
        for c in self.cameras:
            self.renderer.update_scene(self.physics.data.ptr, camera=c)
            out.append(np.ascontiguousarray(self.renderer.render(), dtype=np.uint8).tobytes())
        return out

    def _observation(self, render: bool, reward: float) -> Reply:
        q = self.physics.data.qpos
        arms = []
        for k, side in enumerate(("left", "right")):
            a = 8 * k
            body = self.physics.named.data
            pos = body.xpos[f"vx300s_{side}/gripper_link"]
            quat = body.xquat[f"vx300s_{side}/gripper_link"]
            base_pos = body.xpos[f"vx300s_{side}"]
            base_quat = body.xquat[f"vx300s_{side}"]
            arms.append({"q": q[a:a + 6].tolist(), "gripper_q": q[a + 6:a + 8].tolist(),
                         "flange": _in_base(pos, quat, base_pos, base_quat)})
        success = reward >= 4
        self.success = self.success or success
        images = self._images(render)
        return {"step": self.step_index, "arms": arms, "success": bool(success),
                "succeeded": self.success, "reward": float(reward),
                "done": self.step_index >= STEPS, "render": bool(render),
                "images": [{"camera": c, "width": self.width, "height": self.height}
                           for c in (self.cameras if render else [])]}, images

    def reset(self, req: Dict[str, Any]) -> Reply:
        seed = int(req["seed"])
        self.objects = self._draw(seed)
        self.plan = self._expert_plan()
        self.joint_tasks.BOX_POSE[0] = np.asarray(self.objects).copy()
        self.joint.reset()
        self.step_index = 0
        self.success = False
        self._gripper = [float(self.plan[0][6]), float(self.plan[0][13])]
        # No command yet: each arm holds its starting posture.
        q = self.physics.data.qpos
        self._target = [q[0:6].copy(), q[8:14].copy()]
        return self._observation(req.get("render", True), 0.0)

    def _act(self, action: np.ndarray, render: bool) -> Reply:
        if self.step_index >= STEPS:
            raise ValueError(f"the episode already took its {STEPS} steps: reset it")
        ts = self.joint.step(action)
        self.step_index += 1
        return self._observation(render, float(ts.reward or 0.0))

    def step(self, req: Dict[str, Any]) -> Reply:
        cmds = req.get("commands") or []
        if len(cmds) != 2:
            raise ValueError(f"ALOHA has two arms: {len(cmds)} commands")
        action = np.zeros(14)
        for k, c in enumerate(cmds):
            joints = c.get("joints")
            if joints is None and c.get("pose") is not None:
                raise ValueError("ALOHA's arms take joint targets (a leader arm's JointState), "
                                 "not TCP poses")
            if joints is not None:
                if len(joints) != 6:
                    raise ValueError(f"arm {k}: {len(joints)} joint targets, not 6")
                self._target[k] = np.asarray(joints, dtype=np.float64)
            action[7 * k:7 * k + 6] = self._target[k]
            w = c.get("gripper_width_m")
            if w is not None:
                self._gripper[k] = float(np.clip(normalized_of(float(w)), 0.0, 1.0))
            action[7 * k + 6] = self._gripper[k]
        if not np.all(np.isfinite(action)):
            raise ValueError("non-finite joint targets")
        return self._act(action, req.get("render", True))

    def expert_step(self, req: Dict[str, Any]) -> Reply:
        a = self.plan[min(self.step_index, len(self.plan) - 1)]
        commands = [{"joints": a[7 * k:7 * k + 6].tolist(), "gripper_width_m": width_of(a[7 * k + 6])}
                    for k in range(2)]
        self._gripper = [float(a[6]), float(a[13])]
        self._target = [a[0:6].copy(), a[7:13].copy()]
        header, blobs = self._act(np.asarray(a), req.get("render", True))
        header["commands"] = commands
        return header, blobs


def _in_base(pos, quat, base_pos, base_quat) -> List[float]:
    """A world pose (xyz, wxyz) expressed in an arm's base frame."""
    from scipy.spatial.transform import Rotation as R

    rb = R.from_quat([base_quat[1], base_quat[2], base_quat[3], base_quat[0]])
    p = rb.inv().apply(np.asarray(pos) - np.asarray(base_pos))
    r = rb.inv() * R.from_quat([quat[1], quat[2], quat[3], quat[0]])
    x, y, z, w = r.as_quat()
    return p.tolist() + [float(w), float(x), float(y), float(z)]


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)
