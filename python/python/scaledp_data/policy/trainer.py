"""The training run behind ``python -m scaledp_data.train`` (one process, or one rank of a
``torchrun`` job): the Rust trainer's loop (``policy/src/trainer/``) in PyTorch.

Per step: each rank takes its disjoint share of the global batch from the Rust loader
(:class:`scaledp_data.torch.ScaleDPIterableDataset`, sharded by rank: rank ``r`` holds rows
``r, r + W, ...`` of the global batch), the step's draws are made for the whole global batch
from a generator seeded by (seed, step) and each rank takes its rows, the summed squared error
is divided by the global number of terms (so DDP's gradient average is the global loss's
gradient), AdamW at the cosine schedule's rate (optional clipping), then the EMA. One process
with batch B and W ranks with B / W each therefore compute the same update. Validation,
checkpoints and ``metrics.jsonl`` are rank 0's.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

import torch
import torch.distributed as dist

from . import checkpoint as ckpt
from .diffusion import DenoisingLoss, Draws, NoiseScheduler
from .model import ImagePolicy, build_policy
from .options import cosine_lr, ema_decay, encoder_decay
from .validation import validate

__all__ = ["Dist", "Trainer", "Diverged"]


class Diverged(RuntimeError):
    """The loss became NaN or infinite."""


@dataclass
class Dist:
    """Where this process sits: rank, world size, device (one per rank)."""

    rank: int = 0
    world: int = 1
    device: torch.device = torch.device("cpu")

    @property
    def main(self) -> bool:
        """Whether this is rank 0 (progress, validation, checkpoints, metrics)."""
        return self.rank == 0

    def all_sum(self, values: List[float]) -> List[float]:
        """Element-wise sum over the ranks (float64)."""
        if self.world == 1:
            return list(values)
        t = torch.tensor(values, dtype=torch.float64, device=self.device)
        dist.all_reduce(t)
        return t.tolist()

    def all_gather(self, value: float) -> List[float]:
        """Every rank's ``value``, by rank."""
        if self.world == 1:
            return [value]
        t = torch.zeros(self.world, dtype=torch.float64, device=self.device)
        t[self.rank] = value
        dist.all_reduce(t)
        return t.tolist()

    def barrier(self) -> None:
        """Waits for every rank."""
        if self.world > 1:
            dist.barrier()


def step_generator(seed: int, step: int) -> torch.Generator:
    """The generator of step ``step``'s draws: the same on every rank, independent of the ranks'
    count, so a resumed run draws what an uninterrupted one would."""
    h = hashlib.blake2b(f"scaledp-step:{seed}:{step}".encode(), digest_size=8).digest()
    return torch.Generator().manual_seed(int.from_bytes(h, "little") & ((1 << 63) - 1))


def is_decayed(name: str) -> bool:
    """Linear and Conv weights and DP-T's attention in-projections (what the Rust builder marks
    for weight decay); not the norms' weights (GroupNorm ``bn*``/``downsample.1``, DP-T's
    LayerNorms)."""
    if name.endswith(".in_proj_weight"):
        return True
    norms = (".bn", "downsample.1", ".norm", "ln_f.")
    return name.endswith(".weight") and not any(n in name for n in norms)


def param_groups(policy: ImagePolicy, o: Dict[str, Any]) -> List[Dict[str, Any]]:
    """diffusion_policy's groups: every encoder tensor at ``encoder_weight_decay``, the
    denoiser's Linear weights at ``weight_decay``, the rest undecayed."""
    enc_wd, wd = encoder_decay(o), o["adamw"]["weight_decay"]
    groups: Dict[float, List[torch.nn.Parameter]] = {}
    for name, p in policy.named_parameters():
        if name.startswith("obs_encoder.") and enc_wd is not None:
            decay = enc_wd
        else:
            decay = wd if is_decayed(name) else 0.0
        groups.setdefault(decay, []).append(p)
    return [{"params": ps, "weight_decay": d} for d, ps in groups.items()]


def _legacy(o: Dict[str, Any]) -> Dict[str, Any]:
    """Options of runs saved before a setting existed, as they started."""
    o = dict(o)
    o.setdefault("loss", {"noise_samples": 1, "mask_padding": True})
    o.setdefault("state_norm", "mean_std")
    o.setdefault("image_range", "unit")
    o.setdefault("attention", "non_causal")
    o.setdefault("arch", "scale_dp")
    o.setdefault("dropout", None)
    o.setdefault("pos_embed", "learned")
    return o


def open_loaders(dataset: str, o: Dict[str, Any], d: Dist):
    """This rank's training share (global batch / W) and, on rank 0, the validation loader."""
    from scaledp_data import Loader
    from scaledp_data.torch import ScaleDPIterableDataset

    if o["batch_size"] % d.world:
        raise ValueError(f"--batch-size {o['batch_size']} does not split over {d.world} ranks: "
                         "use a multiple of the world size")
    base = dict(obs_horizon=o["obs_horizon"], action_chunk=o["action_chunk"],
                val_ratio=o["val_ratio"], split_seed=o["seed"], seed=o["seed"], shuffle=True,
                threads=o["loader_threads"], state_norm=o["state_norm"], action_norm="min_max",
                cameras=o["cameras"], image_size=tuple(o["image_size"]) if o["image_size"] else None)
    split = "train" if o["val_ratio"] > 0 else "all"
    per_rank = o["batch_size"] // d.world
    train = dict(base, split=split, batch_size=per_rank, max_episodes=o["max_episodes"])
    ds = ScaleDPIterableDataset(dataset, rank=d.rank, world_size=d.world,
                                drop_incomplete_batch=True, **train)
    if len(ds) == 0:  # full batches only, unless the split is smaller than one batch
        ds = ScaleDPIterableDataset(dataset, rank=d.rank, world_size=d.world, **train)
    val = None
    if o["val_ratio"] > 0 and d.main:
        try:
            val = Loader(dataset, split="val", batch_size=o["batch_size"], **base)
        except ValueError as e:
            if "no samples" not in str(e):
                raise
            print(f"warning: {dataset}: no validation episodes at val_ratio {o['val_ratio']}",
                  flush=True)
    return ds, val


class Trainer:
    """A run in a directory (``metrics.jsonl``, ``checkpoints/step_*``): :meth:`new` or
    :meth:`resume`, then :meth:`step` / :meth:`run`."""

    def __init__(self, dataset: str, out: str, o: Dict[str, Any], d: Dist,
                 resume_from: Optional[str] = None):
        self.o, self.d, self.out = o, d, out
        self.train_ds, self.val = open_loaders(dataset, o, d)
        self.cfg = ckpt.checkpoint_config(dataset, self.train_ds.info,
                                          self.train_ds.normalizer.numpy, o)
        self.scheduler = NoiseScheduler(self.cfg["diffusion"]["train_steps"])
        self.policy = build_policy(self.cfg["model"])
        self.policy.initialize(torch.Generator().manual_seed(o["seed"]))
        self.step_count = 0
        if resume_from is not None:
            self._load(resume_from)
        self.policy.to(d.device)
        self.ema = {k: v.detach().clone() for k, v in self.policy.state_dict().items()}
        if resume_from is not None:
            self._load_ema(resume_from)
        a = o["adamw"]
        self.optim = torch.optim.AdamW(param_groups(self.policy, o), lr=o["lr"],
                                       betas=(a["beta1"], a["beta2"]), eps=a["eps"])
        if resume_from is not None:
            self._load_moments(resume_from)
        self.loss = DenoisingLoss(self.policy, self.scheduler, o["loss"]["mask_padding"]).to(d.device)
        if d.world > 1:
            ids = [d.device.index] if d.device.type == "cuda" else None
            self.net = torch.nn.parallel.DistributedDataParallel(self.loss, device_ids=ids)
        else:
            self.net = self.loss
        self._it = None
        self.stop = False
        self.samples = None
        self.metrics = None
        if d.main:
            os.makedirs(out, exist_ok=True)
            self.metrics = self._open_metrics(resume_from is not None)
        d.barrier()

    # --- construction -------------------------------------------------------------------
    @classmethod
    def new(cls, dataset: str, out: str, o: Dict[str, Any], d: Dist) -> Trainer:
        """A new run; ``out`` must not hold checkpoints already."""
        if ckpt.list_checkpoints(out):
            raise ValueError(f"{out} already holds checkpoints: resume it, or choose another --out")
        return cls(dataset, out, o, d)

    @classmethod
    def resume(cls, run: str, steps: Optional[int], d: Dist) -> Trainer:
        """Continues ``run`` from its latest checkpoint (either trainer's): weights, EMA, AdamW
        moments, data position and the step's draws; ``steps`` changes the total."""
        found = ckpt.list_checkpoints(run)
        if not found:
            raise FileNotFoundError(f"{run}: no checkpoints/step_* to resume from")
        path = found[-1][1]
        cfg = ckpt.read_config(path)
        o = _legacy(cfg["train"])
        if steps is not None:
            o["steps"] = steps
        t = cls(cfg["dataset"], run, o, d, resume_from=path)
        if t.cfg["model"] != cfg["model"] or t.cfg["normalizer"] != cfg["normalizer"]:
            raise ValueError(f"{path}/config.json: the dataset {cfg['dataset']} no longer "
                             "matches the checkpoint's inputs or normalizer")
        return t

    def _load(self, path: str) -> None:
        params, self._moments = ckpt.read_train_state(path)
        self.policy.load_state_dict(params, strict=True)
        cfg = ckpt.read_config(path)
        self.step_count = int(cfg["step"])
        state = cfg.get("loader")
        if state is not None:
            pos = int(state["position"])
            if pos % self.d.world:
                raise ValueError(f"{path}/config.json: loader position {pos} does not split over "
                                 f"{self.d.world} ranks")
            self.train_ds.load_state_dict({"epoch": int(state["epoch"]), "position": pos // self.d.world})

    def _load_ema(self, path: str) -> None:
        from safetensors.torch import load_file

        ema = load_file(os.path.join(path, ckpt.MODEL_FILE))
        if set(ema) != set(self.ema):
            raise ValueError(f"{path}/{ckpt.MODEL_FILE}: not the weights of this model")
        self.ema = {k: v.to(self.d.device, torch.float32) for k, v in ema.items()}

    def _load_moments(self, path: str) -> None:
        step = torch.tensor(float(self.step_count))
        for name, p in self.policy.named_parameters():
            m = self._moments.get(name)
            if m is None or set(m) != {"exp_avg", "exp_avg_sq"}:
                raise ValueError(f"{path}/{ckpt.TRAIN_STATE_FILE}: no AdamW moments of {name}")
            self.optim.state[p] = {"step": step.clone(), "exp_avg": m["exp_avg"].to(p.device),
                                   "exp_avg_sq": m["exp_avg_sq"].to(p.device)}
        del self._moments

    def _open_metrics(self, resumed: bool):
        return _reopen(os.path.join(self.out, "metrics.jsonl"), self.step_count if resumed else None)

    def log_samples(self) -> None:
        """Write ``samples-rank<R>.jsonl``: each step's (episode_index, frame_index) pairs of
        this rank (for checking what every rank trained on)."""
        os.makedirs(self.out, exist_ok=True)
        path = os.path.join(self.out, f"samples-rank{self.d.rank}.jsonl")
        self.samples = _reopen(path, self.step_count if self.step_count else None)

    # --- the loop -----------------------------------------------------------------------
    def next_batch(self) -> Dict[str, torch.Tensor]:
        """This rank's next batch, starting a new epoch when one ends."""
        for _ in range(2):
            if self._it is None:
                self._it = iter(self.train_ds)
            try:
                return next(self._it)
            except StopIteration:
                self._it = None
        raise RuntimeError(f"{self.cfg['dataset']}: the training split yields no batches")

    def step(self) -> Dict[str, Any]:
        """One optimizer step; returns its ``metrics.jsonl`` record (rank 0's view of it)."""
        o, d = self.o, self.d
        t0 = time.perf_counter()
        batch = self.next_batch()
        wait = time.perf_counter() - t0
        _check_finite(batch)
        dev = d.device
        b = batch["action"].shape[0]
        spec = o["loss"]
        k = max(1, spec["noise_samples"])
        draws = Draws.random(self.cfg["model"], b * d.world, k, self.scheduler.train_steps,
                             step_generator(o["seed"], self.step_count))
        mine = draws.select(torch.arange(d.rank, b * d.world, d.world)).to(dev)
        pad = batch["action_is_pad"]
        # The global number of squared errors the loss averages (loss.rs: steps x A x K).
        steps = float((~pad).sum()) if spec["mask_padding"] else float(pad.numel())
        denom = max(d.all_sum([steps])[0], 1.0) * self.cfg["model"]["action_dim"] * k
        lr = cosine_lr(o["lr"], self.step_count, o["warmup_steps"], o["steps"])
        for g in self.optim.param_groups:
            g["lr"] = lr
        self.optim.zero_grad(set_to_none=True)
        # Dropout (DP-T) draws from torch's global generator: seeded per step and rank, so a
        # resumed run drops what an uninterrupted one would.
        torch.manual_seed(int(torch.randint(0, 1 << 62, (1,),
                                            generator=step_generator(o["seed"] ^ 0xD0, self.step_count)))
                          + d.rank)
        self.policy.train()
        micro = min(max(o["micro_batch"] or b, 1), b)
        starts = list(range(0, b, micro))
        total = torch.zeros((), dtype=torch.float64, device=dev)
        for i, s0 in enumerate(starts):
            sl = slice(s0, min(s0 + micro, b))
            sync = i == len(starts) - 1 or d.world == 1
            ctx = contextlib.nullcontext() if sync else self.net.no_sync()
            with ctx:
                part = self.net(
                    batch["observation.images"][sl].to(dev, non_blocking=True),
                    batch["observation.state"][sl].to(dev, non_blocking=True),
                    batch["action"][sl].to(dev, non_blocking=True),
                    pad[sl].to(dev, non_blocking=True),
                    mine.crops[:, sl], mine.timesteps[sl], mine.noise[sl])
                (part * (d.world / denom)).backward()
            total += part.detach().to(torch.float64)
        loss = d.all_sum([float(total)])[0] / denom
        if not torch.isfinite(torch.tensor(loss)):
            raise Diverged(f"the loss became {loss} at step {self.step_count + 1}")
        norm = None
        if o["grad_clip"] is not None:
            norm = float(torch.nn.utils.clip_grad_norm_(self.policy.parameters(), o["grad_clip"]))
        self.optim.step()
        self._ema_update(ema_decay(o["ema"], self.step_count))
        self.step_count += 1
        state = self.train_ds.state_dict()
        waits = d.all_gather(wait)
        rec = {"step": self.step_count, "loss": loss, "lr": lr, "grad_norm": norm,
               "samples": b * d.world, "step_s": time.perf_counter() - t0,
               "data_wait_s": wait, "epoch": state["epoch"]}
        if d.world > 1:
            rec["ranks"] = d.world
            rec["data_wait_s_per_rank"] = waits
        self.log({"kind": "train", "record": rec})
        if self.samples is not None:
            self.samples.write(json.dumps({"record": {
                "step": self.step_count, "episode_index": batch["episode_index"].tolist(),
                "frame_index": batch["frame_index"].tolist()}}) + "\n")
            self.samples.flush()
        return rec

    @torch.no_grad()
    def _ema_update(self, decay: float) -> None:
        d32 = float(torch.tensor(decay, dtype=torch.float32))
        keep = float(torch.tensor(1.0, dtype=torch.float32) - torch.tensor(decay, dtype=torch.float32))
        # A fixed table (requires_grad=False) stays bit for bit, as in the Rust trainer.
        fixed = {n for n, p in self.policy.named_parameters() if not p.requires_grad}
        for name, p in self.policy.state_dict().items():
            if name not in fixed:
                self.ema[name].mul_(d32).add_(p, alpha=keep)

    def validate(self) -> Optional[Dict[str, Any]]:
        """Rank 0 validates the EMA weights on held-out episodes; the others wait."""
        rec = None
        if self.d.main and self.val is not None:
            model = build_policy(self.cfg["model"]).to(self.d.device).eval()
            model.load_state_dict(self.ema, strict=True)
            rec = validate(model, self.cfg, self.val, self.o["val_batches"], self.o["seed"],
                           self.step_count, self.d.device)
            self.log({"kind": "val", "record": rec})
        self.d.barrier()
        return rec

    def save_checkpoint(self) -> Optional[str]:
        """Rank 0 writes the checkpoint of the current step; returns its directory there."""
        path = None
        if self.d.main:
            self.metrics.flush()
            pos = self.train_ds.state_dict()
            cfg = dict(self.cfg, step=self.step_count, train=self.o,
                       loader={"epoch": pos["epoch"], "position": pos["position"] * self.d.world})
            names = dict((id(p), n) for n, p in self.policy.named_parameters())
            moments = {}
            for p, s in self.optim.state.items():
                moments[names[id(p)]] = (s["exp_avg"], s["exp_avg_sq"])
            for n, p in self.policy.named_parameters():
                if n not in moments:
                    moments[n] = (torch.zeros_like(p), torch.zeros_like(p))
            path = ckpt.write(self.out, self.step_count, cfg, self.ema, self.policy.state_dict(), moments)
        self.d.barrier()
        return path

    def close(self) -> None:
        """Closes ``metrics.jsonl`` and drops the DDP wrapper, the optimizer and the loaders, so
        the process group's last users are gone before it is destroyed."""
        if self.metrics is not None:
            self.metrics.close()
            self.metrics = None
        self._it = None
        self.net = self.loss = self.optim = None
        self.train_ds = self.val = None

    def log(self, v: Dict[str, Any]) -> None:
        """Appends a line to ``metrics.jsonl`` (rank 0)."""
        if self.metrics is not None:
            self.metrics.write(json.dumps(v) + "\n")
            self.metrics.flush()

    def run(self, on=lambda kind, value: None) -> Dict[str, Any]:
        """Trains to the total step count, validating and saving as the options say, and always
        saving at the end (or when :attr:`stop` was set, from a signal handler: every rank
        stops after the same step). ``on(kind, value)`` sees every step, validation and
        checkpoint on rank 0."""
        o = self.o
        recent: List[float] = []
        wait = busy = 0.0
        interrupted = False
        last = None
        while self.step_count < o["steps"]:
            if self.d.all_sum([1.0 if self.stop else 0.0])[0] > 0:
                interrupted = True
                break
            rec = self.step()
            wait, busy = wait + rec["data_wait_s"], busy + rec["step_s"]
            recent = (recent + [rec["loss"]])[-50:]
            on("step", rec)
            k = self.step_count
            if o["val_every"] > 0 and k % o["val_every"] == 0 and k < o["steps"]:
                v = self.validate()
                if v is not None:
                    on("val", v)
            if o["checkpoint_every"] > 0 and k % o["checkpoint_every"] == 0 and k < o["steps"]:
                last = self.save_checkpoint()
                on("checkpoint", last)
        if o["val_every"] > 0 and not interrupted:
            v = self.validate()
            if v is not None:
                on("val", v)
        last = self.save_checkpoint()
        on("checkpoint", last)
        return {"steps": self.step_count, "checkpoint": last,
                "final_loss": sum(recent) / len(recent) if recent else None,
                "data_wait_share": wait / busy if busy > 0 else 0.0, "interrupted": interrupted}


def _reopen(path: str, step: Optional[int]):
    """``path`` for appending after keeping its lines up to ``step`` (a crash after the last
    checkpoint left later ones), or emptied when ``step`` is None (a new run)."""
    if step is None:
        return open(path, "w")
    kept = []
    with contextlib.suppress(FileNotFoundError), open(path) as f:
        for line in f:
            with contextlib.suppress(ValueError, KeyError, TypeError):
                if json.loads(line)["record"]["step"] <= step:
                    kept.append(line)
    with open(path, "w") as f:
        f.writelines(kept)
    return open(path, "a")


def _check_finite(b: Dict[str, torch.Tensor]) -> None:
    """Refuses a batch with a non-finite state or action value, naming its sample."""
    for what, key in (("state", "observation.state"), ("action", "action")):
        bad = ~torch.isfinite(b[key].reshape(b[key].shape[0], -1)).all(dim=1)
        if bool(bad.any()):
            s = int(bad.nonzero()[0])
            raise ValueError(f"a non-finite {what} value in episode "
                             f"{int(b['episode_index'][s])}, frame {int(b['frame_index'][s])}")
