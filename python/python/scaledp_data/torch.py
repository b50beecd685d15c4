"""``torch.utils.data`` adapter for :class:`scaledp_data.Loader` (needs torch; importing
``scaledp_data`` alone never imports it).

The loader already batches, decodes on its own thread pool and prefetches, so the usual way is::

    ds = ScaleDPIterableDataset("datasets/cups", batch_size=64, split="train", val_ratio=0.1)
    dl = torch.utils.data.DataLoader(ds, batch_size=None, num_workers=0, pin_memory=True)

``batch_size=None`` because each item already is a batch; ``num_workers=0`` because worker
processes add nothing but copies through shared memory. ``num_workers > 0`` works too: each
worker then reads its own disjoint share of the samples (it acts as one more DDP rank), but
``state_dict()`` / ``load_state_dict()`` and the automatic epoch advance only work with
``num_workers=0`` -- with workers call ``set_epoch(epoch)`` before every epoch; with
``persistent_workers=True`` the workers cannot hear it and instead advance one epoch per pass
from the epoch set when the DataLoader started them.

DDP: rank and world size come from ``torch.distributed`` when it is initialized (else 0 of 1);
every rank yields the same number of batches. Use the same ``seed`` on every rank.
"""

from __future__ import annotations

import os
from typing import Any, Dict, Iterator, Optional

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data import IterableDataset, get_worker_info

from . import Loader, Normalizer

__all__ = ["ScaleDPIterableDataset", "TorchNormalizer"]


class TorchNormalizer:
    """A :class:`scaledp_data.Normalizer` on torch tensors: each method returns a float32 tensor on
    the input's device (the arithmetic runs on the CPU, in the loader's own code, so training
    and deployment normalize identically)."""

    def __init__(self, normalizer: Normalizer):
        self.numpy = normalizer

    def _apply(self, fn, x: torch.Tensor) -> torch.Tensor:
        out = fn(x.detach().to("cpu", torch.float32).numpy())
        return torch.from_numpy(out).to(x.device)

    def normalize_state(self, x: torch.Tensor) -> torch.Tensor:
        return self._apply(self.numpy.normalize_state, x)

    def unnormalize_state(self, x: torch.Tensor) -> torch.Tensor:
        return self._apply(self.numpy.unnormalize_state, x)

    def normalize_action(self, x: torch.Tensor) -> torch.Tensor:
        return self._apply(self.numpy.normalize_action, x)

    def unnormalize_action(self, x: torch.Tensor) -> torch.Tensor:
        return self._apply(self.numpy.unnormalize_action, x)


def _to_torch(batch: Dict[str, np.ndarray]) -> Dict[str, torch.Tensor]:
    # torch.from_numpy shares the array's memory: the Rust buffer is never copied.
    return {k: torch.from_numpy(v) for k, v in batch.items()}


class ScaleDPIterableDataset(IterableDataset):
    """Batches of a :class:`scaledp_data.Loader` as dicts of torch tensors.

    Takes the loader's arguments (``location`` and the same keyword options). ``rank`` /
    ``world_size`` default to ``torch.distributed``'s when it is initialized, else 0 / 1.
    """

    def __init__(self, location: Any, *, rank: Optional[int] = None,
                 world_size: Optional[int] = None, **options: Any):
        super().__init__()
        if (rank is None) != (world_size is None):
            raise ValueError("give both rank and world_size, or neither")
        if rank is None:
            if dist.is_available() and dist.is_initialized():
                rank, world_size = dist.get_rank(), dist.get_world_size()
            else:
                rank, world_size = 0, 1
        self.location = location if isinstance(location, str) else os.fspath(location)
        self.rank, self.world_size = int(rank), int(world_size)
        self.options = dict(options)
        self.epoch = 0
        # In a DataLoader worker: its own loader, and how many epochs it has served.
        self._worker_loader: Optional[Loader] = None
        self._worker_passes = 0
        # Opened here so that bad options fail at once; never pickled to workers.
        self._loader: Optional[Loader] = Loader(
            self.location, rank=self.rank, world_size=self.world_size, **self.options)

    # --- what the main-process loader knows -----------------------------------------------
    def __len__(self) -> int:
        """Batches per epoch of this rank (with ``num_workers=0``)."""
        return len(self._main())

    @property
    def num_samples(self) -> int:
        return self._main().num_samples

    @property
    def info(self) -> Dict[str, Any]:
        return self._main().info

    @property
    def normalizer(self) -> TorchNormalizer:
        return TorchNormalizer(self._main().normalizer)

    def set_epoch(self, epoch: int) -> None:
        """Uses epoch ``epoch``'s order from its start -- unless the loader is already in that
        epoch (e.g. just resumed there, or it advanced to it by finishing the previous one), in
        which case it goes on where it is."""
        self.epoch = int(epoch)
        loader = self._main()
        if loader.epoch != self.epoch:
            loader.set_epoch(self.epoch)

    def state_dict(self) -> Dict[str, int]:
        """Where the next batch starts (``num_workers=0`` only): save it with the checkpoint."""
        return self._main().state_dict()

    def load_state_dict(self, state: Dict[str, int]) -> None:
        """Continues from a ``state_dict()`` of a dataset with the same options."""
        loader = self._main()
        loader.load_state_dict(state)
        self.epoch = loader.epoch

    # --- iteration --------------------------------------------------------------------------
    def __iter__(self) -> Iterator[Dict[str, torch.Tensor]]:
        worker = get_worker_info()
        if worker is None:
            loader = self._main()
            if loader.epoch != self.epoch:
                loader.set_epoch(self.epoch)
            for batch in loader:
                yield _to_torch(batch)
            # The loader moved on to the next epoch when this one ended.
            self.epoch = loader.epoch
            return
        # A DataLoader worker process: it reads every (world_size * num_workers)-th sample of
        # the epoch's permutation, so workers and ranks never share a sample.
        # A worker's copy of the dataset was made when the workers started: with
        # persistent_workers it serves every epoch, and set_epoch() in the main process never
        # reaches it, so it counts its own passes from the epoch it was created in.
        n = worker.num_workers
        options = dict(self.options)
        if options.get("threads", 0) == 0:
            options["threads"] = max(1, (os.cpu_count() or 1) // n)
        if self._worker_loader is None:
            self._worker_loader = Loader(self.location, rank=self.rank * n + worker.id,
                                         world_size=self.world_size * n, **options)
        loader = self._worker_loader
        loader.set_epoch(self.epoch + self._worker_passes)
        self._worker_passes += 1
        for batch in loader:
            yield _to_torch(batch)

    def _main(self) -> Loader:
        if self._loader is None:  # an unpickled copy (a worker) asked for it
            self._loader = Loader(self.location, rank=self.rank, world_size=self.world_size,
                                  **self.options)
        return self._loader

    def __getstate__(self) -> Dict[str, Any]:
        state = self.__dict__.copy()
        state["_loader"] = None
        state["_worker_loader"] = None
        state["_worker_passes"] = 0
        return state
