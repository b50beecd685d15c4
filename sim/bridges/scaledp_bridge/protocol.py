"""The bridge protocol between a simulator in this process and the Rust side
(``sim/src/bridge/``): one request per line on stdin (JSON), one framed response on stdout.

A response is a 4-byte little-endian length, that many bytes of JSON (the header), then the
binary payload the header announces (``"payload": n`` bytes: the camera images, each
height x width x 3 RGB bytes, in the order of ``"images"``). Errors are ``{"ok": false,
"error": "..."}`` headers; the process keeps serving after one (a bad request is not fatal).

Requests (``"op"``):

- ``hello``: the simulator's description (``step_s``, ``max_steps``, cameras, arms, versions).
- ``reset`` (``seed``): the episode of that seed; returns the first observation.
- ``step`` (``commands``: per arm ``{"pose": [x, y, z, qw, qx, qy, qz]`` in the arm's base
  frame, or ``"joints": [...]``, and ``"gripper_width_m"``}): one control step; returns the
  next observation.
- ``expert_step``: one step of the simulator's scripted expert; returns the next observation
  and, under ``"commands"``, what the expert commanded, in the form ``step`` takes.
- ``close``: the process exits.

Every observation carries ``render`` (whether images were drawn: ``"render": false`` in a
request skips them, for a real-time loop that has fallen behind).
"""

from __future__ import annotations

import json
import struct
import sys
import traceback
from typing import Any, Callable, Dict, List, Optional, Tuple

__all__ = ["serve", "Reply", "claim_stdout"]

#: A reply: the JSON header and the images (bytes) to append.
Reply = Tuple[Dict[str, Any], List[bytes]]


_OUT = None


def claim_stdout() -> None:
    """Keeps the process's stdout for the protocol alone: its file descriptor is duplicated for
    the replies, and fd 1 then points at stderr, so a stray ``print`` or a C library's message
    (MuJoCo, EGL) can never corrupt a reply."""
    global _OUT
    import os

    sys.stdout.flush()
    _OUT = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr


def _write(header: Dict[str, Any], blobs: List[bytes]) -> None:
    out = _OUT if _OUT is not None else sys.stdout.buffer
    header = dict(header)
    header["payload"] = sum(len(b) for b in blobs)
    data = json.dumps(header, separators=(",", ":")).encode()
    out.write(struct.pack("<I", len(data)))
    out.write(data)
    for b in blobs:
        out.write(b)
    out.flush()


def serve(handlers: Dict[str, Callable[[Dict[str, Any]], Reply]]) -> None:
    """Answers requests from stdin until ``close`` or end of input."""
    for line in sys.stdin:
        line = line.strip()
        if not line:
            continue
        try:
            req = json.loads(line)
            op = req.get("op")
            if op == "close":
                _write({"ok": True}, [])
                return
            handler: Optional[Callable] = handlers.get(op)
            if handler is None:
                raise ValueError(f"unknown op {op!r}: one of {sorted(handlers) + ['close']}")
            header, blobs = handler(req)
            header.setdefault("ok", True)
            _write(header, blobs)
        except Exception as e:  # noqa: BLE001 -- every failure goes back to the caller
            traceback.print_exc(file=sys.stderr)
            _write({"ok": False, "error": f"{type(e).__name__}: {e}"}, [])
