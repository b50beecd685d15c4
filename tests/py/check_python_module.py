"""Checks the installed `scaledp_data` module against batches the Rust loader dumped.

Usage: check_python_module.py MANIFEST.json   (tests/tests/python_module.rs writes it)

Per configuration: epochs 0 and 1 byte-equal to the Rust loader's (epoch 1 reached by the
loader's own advance at the end of epoch 0), set_epoch, state_dict after some batches equal to
Rust's, a new loader resumed from it yields the rest byte-equal; the normalizer equal to Rust's
and to the formula on meta/stats.json; errors raise the right exceptions. With torch: the
IterableDataset adapter inside DataLoader (num_workers=0 byte-equal and resumable, num_workers=2
a disjoint cover of the samples, two DDP ranks over gloo). Prints one JSON object; any mismatch
raises (non-zero exit, the reason on stderr).
"""

import json
import os
import socket
import sys
import tempfile
import threading
import time

import numpy as np

import scaledp_data
from scaledp_data import DatasetError, Loader

IMPORTS_TORCH = "torch" in sys.modules


def kwargs_of(c):
    kw = dict(c["kwargs"])
    if "image_size" in kw:
        kw["image_size"] = tuple(kw["image_size"])
    return kw


def load(d, spec):
    a = np.fromfile(os.path.join(d, spec["file"]), dtype=spec["dtype"])
    return a.reshape(spec["shape"])


def same(got, want, what):
    assert isinstance(got, np.ndarray), f"{what}: {type(got)}"
    assert got.dtype == want.dtype, f"{what}: dtype {got.dtype} != {want.dtype}"
    assert got.shape == want.shape, f"{what}: shape {got.shape} != {want.shape}"
    assert got.flags.c_contiguous, f"{what}: not contiguous"
    if got.tobytes() != want.tobytes():
        bad = np.argwhere(got != want)[:5].tolist()
        raise AssertionError(f"{what}: differs from the Rust loader at {bad}")


def same_batch(d, batch, spec, what):
    assert set(batch) == set(spec), f"{what}: keys {sorted(batch)} != {sorted(spec)}"
    for k, s in spec.items():
        same(batch[k], load(d, s), f"{what} {k}")


def owned_by_rust(a):
    """The array's memory belongs to the Rust Vec the loader filled (no copy was made): held by
    numpy's container for a Vec, or, for images, by the ImageBuffer that hands the Vec back to
    the loader's pool when the array is freed."""
    base = a
    while isinstance(base.base, np.ndarray):
        base = base.base
    return not a.flags.owndata and type(base.base).__name__ in ("PySliceContainer", "ImageBuffer")


def check_config(m, c):
    d, ds, kw = m["dir"], m["dataset"], kwargs_of(c)
    epochs = c["epochs"]
    loader = Loader(ds, **kw)
    assert len(loader) == len(epochs[0]["batches"]), (len(loader), c["name"])
    assert loader.num_samples == c["num_samples"]
    info = loader.info
    for k in ("cameras", "episodes", "fps", "state_names", "action_names"):
        assert info[k] == c["info"][k], f"info[{k!r}] {info[k]} != {c['info'][k]}"
    equal = 0
    for e in epochs:
        assert loader.epoch == e["epoch"] and loader.state_dict()["position"] == 0
        # The rest of the epoch (the loader then moves to the next one), each batch dropped
        # before the next: its image buffer goes back to the pool and later batches reuse it.
        n = 0
        for i, b in enumerate(loader):
            assert i < len(e["batches"]), f"{c['name']} epoch {e['epoch']}: too many batches"
            same_batch(d, b, e["batches"][i], f"{c['name']} epoch {e['epoch']} batch {i}")
            assert all(owned_by_rust(a) for a in b.values()), "a batch array was copied"
            img = b["observation.images"]
            assert type(img.base).__name__ == "ImageBuffer", "images not returned to the pool"
            del b, img
            n += 1
            equal += 1
        assert n == len(e["batches"]), f"{c['name']} epoch {e['epoch']}: {n} batches"
    assert loader.state_dict() == {"epoch": len(epochs), "position": 0}, loader.state_dict()

    # set_epoch, a partial epoch, state_dict equal to Rust's, resume in a new loader.
    after, state = c["resume"]["after"], c["resume"]["state"]
    e1 = epochs[1]["batches"]
    loader.set_epoch(1)
    it = iter(loader)
    for i in range(after):
        same_batch(d, next(it), e1[i], f"{c['name']} set_epoch(1) batch {i}")
    assert loader.state_dict() == state, (loader.state_dict(), state)
    resumed = Loader(ds, **kw)
    resumed.load_state_dict(state)
    rest = list(resumed)
    assert len(rest) == len(e1) - after
    for i, b in enumerate(rest):
        same_batch(d, b, e1[after + i], f"{c['name']} resumed batch {after + i}")
    return {"batches_equal": equal, "resumed_batches_equal": len(rest)}


def check_normalizer(m):
    d, n = m["dir"], m["normalizer"]
    norm = Loader(m["dataset"], **kwargs_of(m["configs"][0])).normalizer
    raw_a, raw_s = load(d, n["raw_action"]), load(d, n["raw_state"])
    a, s = norm.normalize_action(raw_a), norm.normalize_state(raw_s)
    same(a, load(d, n["action"]), "normalize_action")
    same(s, load(d, n["state"]), "normalize_state")
    # Any float dtype and any leading shape.
    same(norm.normalize_action(raw_a.astype(np.float64)), a, "normalize_action(float64)")
    same(norm.normalize_action(raw_a.reshape(3, 4, -1)), a.reshape(3, 4, -1), "normalize_action 3-D")
    # Round trips.
    err_a = float(np.abs(norm.unnormalize_action(a) - raw_a).max())
    err_s = float(np.abs(norm.unnormalize_state(s) - raw_s).max())
    assert err_a < 1e-4 and err_s < 1e-4, (err_a, err_s)
    # The formulas on meta/stats.json (defaults: action min_max, state mean_std).
    with open(os.path.join(m["dataset"], "meta/stats.json")) as f:
        st = json.load(f)
    lo, hi = np.array(st["action"]["min"]), np.array(st["action"]["max"])
    # diffusion_policy's rule: a dimension with a range (std) under 1e-4 is only centred.
    flat = hi - lo < 1e-4
    want_a = np.where(flat, raw_a - lo, 2 * (raw_a - lo) / np.where(flat, 1, hi - lo) - 1)
    mean, std = np.array(st["observation.state"]["mean"]), np.array(st["observation.state"]["std"])
    want_s = np.where(std < 1e-4, raw_s - mean, (raw_s - mean) / (std + 1e-8))
    assert np.allclose(a, want_a, atol=1e-5), np.abs(a - want_a).max()
    assert np.allclose(s, want_s, atol=1e-4, rtol=1e-5), np.abs(s - want_s).max()
    assert (norm.action_norm, norm.state_norm) == ("min_max", "mean_std")
    try:
        norm.normalize_action(np.zeros((2, norm.action_dim + 1)))
    except ValueError as e:
        assert "last axis" in str(e), e
    else:
        raise AssertionError("a misshapen array was accepted")
    return {"byte_equal": True, "max_roundtrip_error": max(err_a, err_s)}


def expect(exc, needle, fn):
    try:
        fn()
    except exc as e:
        assert needle in str(e), f"{exc.__name__} without {needle!r}: {e}"
        return 1
    raise AssertionError(f"no {exc.__name__} ({needle})")


def check_errors(m):
    ds = m["dataset"]
    missing = os.path.join(ds, "missing")
    n = expect(FileNotFoundError, missing, lambda: Loader(missing))
    n += expect(ValueError, "bogus", lambda: Loader(ds, split="bogus"))
    n += expect(ValueError, "rank 2", lambda: Loader(ds, rank=2, world_size=2))
    n += expect(ValueError, "min_mad", lambda: Loader(ds, action_norm="min_mad"))
    n += expect(DatasetError, "nosuch", lambda: Loader(ds, cameras=["nosuch"]))
    loader = Loader(ds, batch_size=4)
    n += expect(KeyError, "position", lambda: loader.load_state_dict({"epoch": 0}))
    n += expect(ValueError, "resume", lambda: loader.load_state_dict({"epoch": 0, "position": 10**9}))
    return n


def check_gil(m):
    """While Python waits in next(loader) for a slow batch, another Python thread keeps running
    (the wait releases the GIL; holding it would freeze that thread for the whole call)."""
    loader = Loader(m["dataset"], batch_size=64, image_size=(480, 360), threads=1, prefetch=1)
    steps, stop = [0], [False]

    def spin():
        while not stop[0]:
            steps[0] += 1

    t = threading.Thread(target=spin)
    t.start()
    try:
        time.sleep(0.05)
        a, ta = steps[0], time.perf_counter()
        time.sleep(0.05)
        rate = (steps[0] - a) / (time.perf_counter() - ta)  # steps per second, GIL shared
        a, ta = steps[0], time.perf_counter()
        next(loader)
        during, took = steps[0] - a, time.perf_counter() - ta
    finally:
        stop[0] = True
        t.join()
    ran_ms, took_ms = during / rate * 1e3, took * 1e3
    # Holding the GIL, the other thread runs about one switch interval (5 ms) at the start.
    assert took_ms > 100, f"the batch came too fast ({took_ms:.0f} ms) to tell"
    assert ran_ms > max(0.25 * took_ms, 8e3 * sys.getswitchinterval()), \
        f"the other thread ran {ran_ms:.0f} ms of the {took_ms:.0f} ms wait"
    return {"wait_ms": round(took_ms), "other_thread_ran_ms": round(ran_ms)}


# --- torch ------------------------------------------------------------------------------------

def np_batch(t):
    return {k: v.numpy() for k, v in t.items()}


def samples_of(batches):
    return [(int(e), int(f)) for b in batches for e, f in zip(b["episode_index"], b["frame_index"])]


def ddp_rank(rank, port, ds, kw, out):
    import torch.distributed as dist
    from torch.utils.data import DataLoader

    from scaledp_data.torch import ScaleDPIterableDataset

    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=2)
    try:
        dl = DataLoader(ScaleDPIterableDataset(ds, **kw), batch_size=None, num_workers=0)
        got = [np_batch(b) for b in dl]
        want = list(Loader(ds, rank=rank, world_size=2, **kw))
        assert len(got) == len(want), (len(got), len(want))
        for g, w in zip(got, want):
            for k in w:
                assert g[k].tobytes() == w[k].tobytes(), f"rank {rank} {k}"
        with open(os.path.join(out, f"rank{rank}.json"), "w") as f:
            json.dump({"batches": len(got), "samples": samples_of(got)}, f)
    finally:
        dist.destroy_process_group()


def check_torch(m):
    try:
        import torch
    except ImportError:
        return "torch not installed: adapter test skipped"
    import torch.multiprocessing as tmp
    from torch.utils.data import DataLoader

    from scaledp_data.torch import ScaleDPIterableDataset

    d, ds, c = m["dir"], m["dataset"], m["configs"][0]
    kw, epochs = kwargs_of(c), c["epochs"]
    dataset = ScaleDPIterableDataset(ds, **kw)
    dl = DataLoader(dataset, batch_size=None, num_workers=0)
    assert len(dl) == len(epochs[0]["batches"])
    equal = 0
    for e in epochs:  # epoch 1 by the adapter's own advance
        got = list(dl)
        assert len(got) == len(e["batches"])
        for i, (t, spec) in enumerate(zip(got, e["batches"])):
            assert t["observation.images"].dtype == torch.uint8
            assert t["action"].dtype == torch.float32 and t["obs_is_pad"].dtype == torch.bool
            assert t["episode_index"].dtype == torch.int64
            same_batch(d, np_batch(t), spec, f"torch epoch {e['epoch']} batch {i}")
            equal += 1
    # set_epoch + partial epoch + resume in a new dataset / DataLoader.
    after, e1 = c["resume"]["after"], epochs[1]["batches"]
    dataset.set_epoch(1)
    it = iter(dl)
    for i in range(after):
        same_batch(d, np_batch(next(it)), e1[i], f"torch set_epoch(1) batch {i}")
    state = dataset.state_dict()
    assert state == c["resume"]["state"], state
    again = ScaleDPIterableDataset(ds, **kw)
    again.load_state_dict(state)
    again.set_epoch(1)  # the usual per-epoch call keeps the resumed position
    rest = list(DataLoader(again, batch_size=None))
    assert len(rest) == len(e1) - after
    for i, t in enumerate(rest):
        same_batch(d, np_batch(t), e1[after + i], f"torch resumed batch {after + i}")
    # Normalizer on tensors.
    tn = dataset.normalizer
    x = torch.from_numpy(load(d, m["normalizer"]["raw_action"]))
    assert torch.allclose(tn.unnormalize_action(tn.normalize_action(x)), x, atol=1e-4)
    # Two worker processes: every sample of the epoch, none twice (beyond the 1-sample padding
    # that makes the shares equal), for fork and spawn.
    everything = sorted(samples_of(list(Loader(ds, **kw))))
    workers = {}
    for ctx in ("fork", "spawn"):
        wd = ScaleDPIterableDataset(ds, **kw)
        wl = DataLoader(wd, batch_size=None, num_workers=2, multiprocessing_context=ctx)
        got = samples_of([np_batch(t) for t in wl])
        pad = len(got) - len(everything)
        assert sorted(set(got)) == everything and 0 <= pad < 2, (ctx, len(got), len(everything))
        workers[ctx] = len(got)
    # Persistent workers never see set_epoch(): they advance one epoch per pass themselves, so
    # two passes give two different orders, each covering the epoch.
    pl = DataLoader(ScaleDPIterableDataset(ds, **kw), batch_size=None, num_workers=2,
                    persistent_workers=True)
    passes = [samples_of([np_batch(t) for t in pl]) for _ in range(2)]
    for p in passes:
        assert sorted(set(p)) == everything, "a persistent-worker pass misses samples"
    assert passes[0] != passes[1], "persistent workers repeated epoch 0's order"
    workers["persistent_passes_differ"] = True
    # DDP: two ranks over gloo on loopback take rank / world from torch.distributed.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with tempfile.TemporaryDirectory() as out:
        tmp.spawn(ddp_rank, args=(port, ds, kw, out), nprocs=2, join=True)
        ranks = []
        for r in range(2):
            with open(os.path.join(out, f"rank{r}.json")) as f:
                ranks.append(json.load(f))
    assert ranks[0]["batches"] == ranks[1]["batches"]
    union = ranks[0]["samples"] + ranks[1]["samples"]
    assert sorted(set(map(tuple, union))) == everything
    return {
        "torch": torch.__version__,
        "dataloader_batches_equal": equal,
        "resumed_batches_equal": len(rest),
        "worker_samples": workers,
        "ddp_batches_per_rank": ranks[0]["batches"],
    }


def main():
    with open(sys.argv[1]) as f:
        m = json.load(f)
    result = {
        "module": scaledp_data.__file__,
        "imports_torch": IMPORTS_TORCH,
        "configs": {c["name"]: check_config(m, c) for c in m["configs"]},
        "normalizer": check_normalizer(m),
        "errors_checked": check_errors(m),
        "gil_released": check_gil(m),
        "torch": check_torch(m),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
