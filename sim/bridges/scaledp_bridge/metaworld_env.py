"""MetaWorld 3.1 (``metaworld``, MuJoCo 3) as a robot the stack can drive.

- One task by name (any of the 50, ``assembly`` or ``assembly-v3``), built from the
  goal-observable class with seeded variations: ``reset(seed)`` seeds the task's generator and
  draws that seed's object and goal placement (deterministic for a seed, unlimited seeds).
- The Sawyer's joints (``right_j0`` ... ``right_j6``) and its two finger joints (``r_close``,
  ``l_close``), read by name (a few tasks declare an object's joint first), are the
  measurements; ``hand`` is the flange (MetaWorld's own end-effector pose).
- A command is a TCP target in the base frame (MetaWorld's world frame) and a gripper opening.
  MetaWorld moves a mocap body by at most 1 cm per step toward it (its action is the
  displacement / 1 cm, clipped to [-1, 1]); the hand's orientation is fixed by MetaWorld
  (mocap quaternion [1, 0, 1, 0], the identity in the rig's TCP frame), so the orientation of a
  target is ignored. The gripper's
  action (+1 closes, -1 opens) maps to an opening command linearly: ``width = 0.094 (1 - a) /
  2`` (0.094 m: the fingers' pads fully open).
- The expert is MetaWorld's scripted policy (``metaworld.policies``); its action is reported as
  the command that reproduces it (the mocap target it sets and the opening it maps to).
- Each step also reports how far the task got by MetaWorld's own flags (its ``info``): stage 1
  ``near_object``, 2 ``grasp_success``, 3 ``success``, the furthest one true at this step, so an
  evaluation can say where a failed episode stopped. Each task defines its flags (assembly's
  ``grasp_success`` is its grab reward above 0.5, button-press's only says the fingers are open).
- Cameras are rendered with ``mujoco.Renderer`` with shadows and multisampling off (about ten
  times cheaper, the picture barely changes); the ``corner*`` cameras come out upside down and
  are flipped.
"""

from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from .cameras import set_up
from .protocol import Reply

#: The fingers' opening (m) with both pads fully open.
OPEN_WIDTH_M = 0.094
ARM_JOINTS = [f"right_j{i}" for i in range(7)]
GRIPPER_JOINTS = ["r_close", "l_close"]
#: MetaWorld's own flags (every task's ``info`` has them), in the order a pick-and-place reaches
#: them: the stages an evaluation counts episodes by (furthest stage >= s).
STAGES = ["near the object", "grasped", "success"]
#: The bridge's behaviour: raised whenever a change to this file can change an episode's
#: outcome, reported in ``hello``'s versions as ``scaledp-bridge`` and recorded with every
#: evaluation, so a result scored by an earlier behaviour shows as such (``experiment compare
#: --rescore`` scores it again).
#:
#: - 1 (no ``scaledp-bridge`` version): ``reset`` kept the previous episode's gripper action, so
#:   an evaluation's first uncommanded ticks closed the fingers after an episode that ended with
#:   them shut (outcomes depended on the order of the episodes; the scripted expert, which
#:   commands its gripper every step, was unaffected).
#: - 2: ``reset`` opens the gripper.
BEHAVIOUR = "2"


def stage_of(info: Dict[str, Any]) -> int:
    """The furthest of MetaWorld's flags true in one step's ``info`` (0 when none is)."""
    for stage, flag in ((3, "success"), (2, "grasp_success"), (1, "near_object")):
        if bool(info.get(flag, False)):
            return stage
    return 0


class MetaWorldEnv:
    """One MetaWorld task behind the bridge protocol."""

    def __init__(self, task: str, cameras: Sequence[str], width: int, height: int,
                 fovy: Optional[Dict[str, float]] = None):
        os.environ.setdefault("MUJOCO_GL", "egl")
        import metaworld
        import mujoco
        from metaworld.env_dict import ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE as envs
        from metaworld.policies import ENV_POLICY_MAP

        name = task if task.endswith("-v3") else f"{task}-v3"
        key = f"{name}-goal-observable"
        if key not in envs:
            names = sorted(k[: -len("-v3-goal-observable")] for k in envs)
            raise ValueError(f"no MetaWorld task {task!r}; the 50 tasks: {', '.join(names)}")
        self.name = name
        self.env = envs[key](seed=0)
        # Seeded variations (not the 50 fixed ones of the benchmark's task list): a seed fixes
        # the object and goal placement, and any seed gives one.
        self.env._freeze_rand_vec = False
        self.env.seeded_rand_vec = True
        self.expert = ENV_POLICY_MAP[name]()
        m = self.env.model
        m.vis.quality.shadowsize = 0
        m.vis.quality.offsamples = 0
        self.camera_info = set_up(m, cameras, width, height, fovy or {}, "MetaWorld")
        self.cameras = list(cameras)
        # Some tasks declare an object's joint before the arm's: read the arm by joint name.
        self.arm_adr = [int(m.jnt_qposadr[m.joint(n).id]) for n in ARM_JOINTS]
        self.finger_adr = [int(m.jnt_qposadr[m.joint(n).id]) for n in GRIPPER_JOINTS]
        self.width, self.height = width, height
        self.renderer = mujoco.Renderer(m, height, width)
        self.mujoco = mujoco
        self.versions = {"metaworld": getattr(metaworld, "__version__", None) or _version("metaworld"),
                         "mujoco": mujoco.__version__, "scaledp-bridge": BEHAVIOUR}
        self.obs = None
        self.step_index = 0
        self.max_steps = int(self.env.max_path_length)
        self.success = False
        #: The gripper action (+1 closes, -1 opens) a step without a gripper command holds.
        self._last_grip = -1.0

    def hello(self) -> Dict[str, Any]:
        return {
            "env": "metaworld", "task": self.name,
            "step_s": float(self.env.model.opt.timestep * self.env.frame_skip),
            "max_steps": self.max_steps,
            "cameras": self.camera_info,
            "arms": [{"joints": ARM_JOINTS, "gripper_joints": GRIPPER_JOINTS}],
            "versions": self.versions,
            "stages": STAGES,
        }

    def _images(self, render: bool) -> List[bytes]:
        if not render:
            return []
        out = []
        for c in self.cameras:
            self.renderer.update_scene(self.env.data, camera=c)
            img = self.renderer.render()
            if c.startswith("corner"):
                img = img[::-1]
            out.append(np.ascontiguousarray(img, dtype=np.uint8).tobytes())
        return out

    def _observation(self, render: bool, info: Dict[str, Any]) -> Reply:
        d = self.env.data
        hand = d.body("hand")
        self.success = self.success or bool(info.get("success", False))
        images = self._images(render)
        header = {
            "step": self.step_index,
            "arms": [{
                "q": d.qpos[self.arm_adr].tolist(),
                "gripper_q": d.qpos[self.finger_adr].tolist(),
                "flange": hand.xpos.tolist() + hand.xquat.tolist(),
            }],
            "success": bool(info.get("success", False)),
            "succeeded": self.success,
            "reward": float(info.get("reward", 0.0)),
            "stage": stage_of(info),
            "done": self.step_index >= self.max_steps,
            "render": bool(render),
            "images": [{"camera": c, "width": self.width, "height": self.height}
                       for c in (self.cameras if render else [])],
        }
        return header, images

    def reset(self, req: Dict[str, Any]) -> Reply:
        seed = int(req["seed"])
        self.env.seed(seed)
        self.obs, info = self.env.reset()
        self.step_index = 0
        self.success = False
        # A step without a gripper command holds the last one: a new episode starts from
        # MetaWorld's reset (fingers open), never from where the previous episode left them.
        self._last_grip = -1.0
        return self._observation(req.get("render", True), {})

    def _act(self, action: np.ndarray, render: bool) -> Reply:
        if self.step_index >= self.max_steps:
            raise ValueError(f"the episode already took MetaWorld's {self.max_steps} steps: reset it")
        self.obs, reward, _, _, info = self.env.step(action.astype(np.float32))
        self.step_index += 1
        info = dict(info)
        info["reward"] = reward
        return self._observation(render, info)

    def step(self, req: Dict[str, Any]) -> Reply:
        cmds = req.get("commands") or []
        if len(cmds) != 1:
            raise ValueError(f"MetaWorld has one arm: {len(cmds)} commands")
        c = cmds[0]
        action = np.zeros(4)
        pose = c.get("pose")
        mocap = self.env.data.mocap_pos[0]
        if pose is not None:
            target = np.asarray(pose[:3], dtype=np.float64)
            if not np.all(np.isfinite(target)):
                raise ValueError(f"non-finite TCP target {pose[:3]}")
            action[:3] = np.clip((target - mocap) / self.env.action_scale, -1.0, 1.0)
        width = c.get("gripper_width_m")
        if width is not None:
            action[3] = np.clip(1.0 - 2.0 * float(width) / OPEN_WIDTH_M, -1.0, 1.0)
        else:
            action[3] = self._last_grip
        self._last_grip = action[3]
        return self._act(action, req.get("render", True))

    def expert_step(self, req: Dict[str, Any]) -> Reply:
        a = np.asarray(self.expert.get_action(self.obs), dtype=np.float64)
        a[:3] = np.clip(a[:3], -1.0, 1.0)
        a[3] = np.clip(a[3], -1.0, 1.0)
        env = self.env
        target = np.clip(env.data.mocap_pos[0] + a[:3] * env.action_scale, env.mocap_low, env.mocap_high)
        # The TCP target's orientation: MetaWorld's fixed hand orientation (mocap quaternion
        # [1, 0, 1, 0]) in the rig's TCP frame (the hand turned -90 degrees about y) is the
        # identity.
        quat = [1.0, 0.0, 0.0, 0.0]
        command = {"pose": target.tolist() + quat,
                   "gripper_width_m": float(OPEN_WIDTH_M * (1.0 - a[3]) / 2.0)}
        self._last_grip = a[3]
        header, blobs = self._act(a, req.get("render", True))
        header["commands"] = [command]
        return header, blobs


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)
