"""Train a ScaleDP policy in PyTorch, in one process or under ``torchrun`` (DistributedDataParallel:
gloo on CPUs, NCCL on GPUs, multi-node through torchrun's rendezvous)::

    python -m scaledp_data.train datasets/cube --model ti --out runs/cube
    torchrun --nproc-per-node 8 -m scaledp_data.train datasets/cube --model l --out runs/cube
    torchrun --nproc-per-node 8 -m scaledp_data.train --resume runs/cube --steps 40000

The flags are ``scaledp train``'s, with the same meanings and defaults (``--batch-size`` is the
global batch, split evenly over the ranks); ``--device`` defaults to ``auto`` (CUDA when there is
one). The run directory is the Rust trainer's: ``metrics.jsonl`` and
``checkpoints/step_N/{model,train_state}.safetensors + config.json``, so ``scaledp serve`` /
``eval`` / ``predict`` take its checkpoints and either trainer resumes the other's runs.
Progress, validation and checkpoints are rank 0's; SIGINT / SIGTERM make every rank stop after
the current step and write a checkpoint.
"""

from __future__ import annotations

import argparse
import datetime
import os
import signal
import sys
import time
from typing import Any, Dict, Optional

__all__ = ["main"]


def _dist(device: str):
    """Joins the process group when torchrun started this process; picks the device."""
    import torch
    import torch.distributed as dist

    from .policy.trainer import Dist

    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda":
        if not torch.cuda.is_available():
            raise ValueError("--device cuda: torch sees no CUDA device")
        torch.cuda.set_device(local)
        dev = torch.device("cuda", local)
    elif device == "cpu":
        dev = torch.device("cpu")
    else:
        raise ValueError(f"--device {device}: cpu, cuda or auto")
    if world > 1:
        dist.init_process_group("nccl" if dev.type == "cuda" else "gloo",
                                timeout=datetime.timedelta(minutes=30))
    return Dist(rank=rank, world=world, device=dev)


def _paper_model(a: argparse.Namespace) -> Dict[str, Any]:
    from .policy.checkpoint import model_config
    from .policy.options import options_from_args

    info = {"image_size": (320, 240), "state_names": ["s"] * 14, "action_names": ["a"] * 14,
            "cameras": [f"observation.images.{c}" for c in ("cam_high", "cam_left_wrist", "cam_right_wrist")]}
    return model_config(info, options_from_args(a))


def print_counts(what: str, m: Dict[str, Any]) -> None:
    """Parameter counts, encoders and denoiser apart (as ``scaledp train --dry-run``)."""
    import torch

    from .policy.model import build_policy, crop_size

    with torch.device("meta"):
        policy = build_policy(m)
    enc = sum(p.numel() for n, p in policy.named_parameters() if n.startswith("obs_encoder."))
    den = sum(p.numel() for n, p in policy.named_parameters() if not n.startswith("obs_encoder."))
    cams = len(m["cameras"])
    cw, ch = crop_size(m)
    name = "DP-T" if m.get("arch") == "dp_t" else f"ScaleDP-{m['size'] or 'custom'}"
    print(f"{what}: {name} (depth {m['depth']}, width {m['hidden']}, "
          f"heads {m['heads']}), {cams} cameras {m['image_width']}x{m['image_height']} cropped to "
          f"{cw}x{ch}, state {m['state_dim']}, action {m['action_dim']}, To {m['obs_horizon']}, "
          f"C {m['action_chunk']}")
    print(f"denoiser parameters: {den} ({den / 1e6:.2f} M)")
    per = enc / cams if cams else 0
    print(f"encoder parameters:  {enc} ({enc / 1e6:.2f} M = {cams} cameras x {per / 1e6:.2f} M)")
    print(f"total parameters:    {enc + den} ({(enc + den) / 1e6:.2f} M)")


class Progress:
    """Rank 0's progress line on stderr (rewritten in place on a terminal, else every ~5 %)."""

    def __init__(self, total: int, start: int):
        self.total, self.start, self.t0 = total, start, time.perf_counter()
        self.tty = sys.stderr.isatty()
        self.wait = self.busy = 0.0
        self.every = max(1, (total - start) // 20)

    def step(self, r: Dict[str, Any]) -> None:
        self.wait += r["data_wait_s"]
        self.busy += r["step_s"]
        k = r["step"]
        done = k - self.start
        eta = (time.perf_counter() - self.t0) / max(done, 1) * (self.total - k)
        line = (f"{k}/{self.total} steps  loss {r['loss']:.4f}  lr {r['lr']:.2e}  "
                f"{r['samples'] / max(r['step_s'], 1e-9):.1f} samples/s  data wait "
                f"{100 * self.wait / max(self.busy, 1e-9):.0f} %  ETA {eta:.0f} s")
        if self.tty:
            print("\r" + line, end="", file=sys.stderr, flush=True)
        elif done % self.every == 0 or k == self.total:
            print(line, file=sys.stderr, flush=True)

    def println(self, text: str) -> None:
        print(("\n" if self.tty else "") + text, file=sys.stderr, flush=True)


class Curves:
    """``--view``: the loss, lr and validation figures in a rerun viewer (``train/loss``,
    ``train/lr``, ``val/<name>`` on the ``step`` timeline, as ``scaledp train --view``)."""

    def __init__(self, url: str, name: str):
        import rerun as rr

        self.rr = rr
        rr.init(f"train: {name}")
        if url:
            rr.connect_grpc(url)
        else:
            rr.spawn()

    def scalar(self, step: int, entity: str, value: float) -> None:
        self.rr.set_time("step", sequence=step)
        self.rr.log(entity, self.rr.Scalars(value))


def run(a: argparse.Namespace) -> int:
    """Runs the command; returns the exit status."""
    from .policy.checkpoint import checkpoint_config, list_checkpoints, read_config
    from .policy.options import options_from_args
    from .policy.trainer import Dist, Trainer, open_loaders

    if a.dry_run:
        if a.resume:
            found = list_checkpoints(a.resume)
            if not found:
                raise FileNotFoundError(f"{a.resume}: no checkpoints/step_* to resume from")
            cfg = read_config(found[-1][1])
            print_counts(cfg["dataset"], cfg["model"])
        elif a.dataset:
            o = options_from_args(a)
            train, _ = open_loaders(a.dataset, o, Dist())
            cfg = checkpoint_config(a.dataset, train.info, train.normalizer.numpy, o)
            print_counts(a.dataset, cfg["model"])
        else:
            print_counts("paper setup (3 cameras, 14-D state and action)", _paper_model(a))
        return 0
    if a.resume and a.out:
        raise ValueError("--resume and --out exclude each other: --resume continues in its own directory")
    if not a.resume and not a.dataset:
        raise ValueError("name a DATASET (or --resume a run)")
    if not a.resume and not a.out:
        raise ValueError("--out DIR is needed for a new run")
    d = _dist(a.device)
    t = None
    try:
        if a.resume:
            t = Trainer.resume(a.resume, a.steps, d)
        else:
            t = Trainer.new(a.dataset, a.out, options_from_args(a), d)
        return _train(t, a, d)
    finally:
        if t is not None:
            t.close()
        del t
        _leave_group()


def _leave_group() -> None:
    """Destroys the process group while the interpreter is whole. gloo's worker threads live
    as long as the group object, which DDP holds; freed at interpreter exit instead, a worker
    that then needs the GIL is ended by Python with a forced unwind that gloo's C++ frames turn
    into ``terminate called without an active exception`` (SIGABRT after a finished run, about
    one run in 20 on 2 CPU ranks here)."""
    import gc

    import torch.distributed as dist

    gc.collect()
    if dist.is_initialized():
        dist.destroy_process_group()
    gc.collect()


def _train(t: Any, a: argparse.Namespace, d: Any) -> int:
    def stop(signum, frame):  # noqa: ARG001
        t.stop = True

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    if a.log_samples:
        t.log_samples()
    bar: Optional[Progress] = None
    curves: Optional[Curves] = None
    if d.main:
        bar = Progress(t.o["steps"], t.step_count)
        m = t.cfg["model"]
        print(f"ScaleDP-{m['size'] or 'custom'} on {t.cfg['dataset']}: {d.world} rank(s) on "
              f"{d.device}, global batch {t.o['batch_size']} ({t.o['batch_size'] // d.world} per "
              f"rank), step {t.step_count} of {t.o['steps']}", file=sys.stderr, flush=True)
        if a.view is not None:
            curves = Curves(a.view, t.cfg["dataset"])

    def on(kind: str, v: Any) -> None:
        if bar is None:
            return
        if kind == "step":
            bar.step(v)
            if curves:
                curves.scalar(v["step"], "train/loss", v["loss"])
                curves.scalar(v["step"], "train/lr", v["lr"])
        elif kind == "val":
            pairs = zip(v["action_names"], v["action_mae_raw"], strict=True)
            dims = ", ".join(f"{n} {e:.4f}" for n, e in pairs)
            bar.println(f"step {v['step']}: val loss {v['loss']:.4f}, action MSE "
                        f"{v['action_mse']:.4f} (normalized), MAE per dim [{dims}]")
            if curves:
                for name in ("loss", "action_mse"):
                    curves.scalar(v["step"], f"val/{name}", v[name])
        elif kind == "checkpoint":
            bar.println(f"checkpoint {v}")

    s = t.run(on)
    if d.main:
        loss = "-" if s["final_loss"] is None else f"{s['final_loss']:.4f}"
        print(f"{s['steps']} steps, final loss {loss}, data wait {100 * s['data_wait_share']:.1f} % "
              f"of step time, checkpoint {s['checkpoint']}", flush=True)
    return 0


def main(argv: Optional[list] = None) -> int:
    """``python -m scaledp_data.train``."""
    from .policy.options import add_arguments

    p = argparse.ArgumentParser(prog="python -m scaledp_data.train", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    a = p.parse_args(argv)
    try:
        return run(a)
    except (ValueError, OSError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        return 1


def _exit(code: int) -> None:
    """Ends a ``torchrun`` rank without the interpreter's finalization (its files are closed and
    its group destroyed by then): torch's C++ objects that outlive the run (a group another
    object still holds, its threads) cannot then be torn down under a finalizing interpreter,
    where a thread needing the GIL aborts the whole rank after a successful run."""
    sys.stdout.flush()
    sys.stderr.flush()
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    _exit(main())
