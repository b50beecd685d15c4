"""``python -m scaledp_bridge --env metaworld --task assembly --cameras corner2,behindGripper
--size 84x84 [--fovy corner2=45]``: one simulator behind the bridge protocol on stdin/stdout (what ``scaledp sim``,
``collect`` and ``eval`` start for a ``metaworld/<task>`` or ``aloha/<task>`` rig)."""

from __future__ import annotations

import argparse
import os
import sys


def main() -> int:
    p = argparse.ArgumentParser(prog="scaledp_bridge", description=__doc__)
    p.add_argument("--env", required=True, choices=["metaworld", "aloha"])
    p.add_argument("--task", required=True)
    p.add_argument("--cameras", required=True, help="comma-separated camera names")
    p.add_argument("--size", default="84x84", help="WxH of every camera")
    p.add_argument("--fovy", default="", help="camera=degrees,...: vertical fields of view that "
                   "replace the model's")
    a = p.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    # One renderer thread: the bridge shares two cores with a recorder and a policy.
    os.environ.setdefault("LP_NUM_THREADS", "1")
    w, h = (int(v) for v in a.size.split("x"))
    cameras = [c for c in a.cameras.split(",") if c]
    from .cameras import parse_fovy
    from .protocol import claim_stdout, serve

    claim_stdout()

    try:
        if a.env == "metaworld":
            from .metaworld_env import MetaWorldEnv

            env = MetaWorldEnv(a.task, cameras, w, h, parse_fovy(a.fovy))
        else:
            from .aloha_env import AlohaEnv

            env = AlohaEnv(a.task, cameras, w, h, parse_fovy(a.fovy))
    except Exception as e:  # noqa: BLE001 -- one line for the caller, then exit
        print(f"scaledp_bridge: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    serve({"hello": lambda r: (env.hello(), []), "reset": env.reset, "step": env.step,
           "expert_step": env.expert_step})
    return 0


if __name__ == "__main__":
    sys.exit(main())
