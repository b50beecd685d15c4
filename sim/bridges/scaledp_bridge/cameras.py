"""The cameras a bridge renders, shared by the MuJoCo simulators: which of the model's cameras,
at what size, and with what vertical field of view (a rig's ``vertical_fov_deg`` replaces the
model's ``fovy``: a zoom that spends a small image's pixels on the workspace)."""

from __future__ import annotations

from typing import Any, Dict, List, Sequence


def parse_fovy(arg: str) -> Dict[str, float]:
    """``top=45,angle=60`` -> {"top": 45.0, "angle": 60.0} (empty for "")."""
    out = {}
    for item in filter(None, arg.split(",")):
        name, sep, deg = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name] = float(deg)
        except ValueError:
            raise ValueError(f"--fovy {item!r}: expected camera=degrees") from None
    return out


def set_up(model, names: Sequence[str], width: int, height: int, fovy: Dict[str, float],
           simulator: str) -> List[Dict[str, Any]]:
    """Checks the cameras exist in ``model`` (a ``mujoco.MjModel``), applies the fields of view
    and returns the cameras as ``hello`` describes them."""
    known = [model.camera(i).name for i in range(model.ncam)]
    for c in list(names) + list(fovy):
        if c not in known:
            raise ValueError(f"{simulator} has no camera {c!r}: {', '.join(known)}")
    for c, deg in fovy.items():
        if c not in names:
            raise ValueError(f"--fovy names camera {c!r}, which is not rendered")
        if not 0.0 < deg < 180.0:
            raise ValueError(f"camera {c!r}: a vertical field of view of {deg} degrees")
        model.cam_fovy[model.camera(c).id] = deg
    return [{"name": c, "width": width, "height": height,
             "fovy_deg": float(model.cam_fovy[model.camera(c).id])} for c in names]
