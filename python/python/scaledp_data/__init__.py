"""scaledp_data: the scaledp training-data loader for Python.

``Loader(location, **options)`` reads a LeRobot v3.0 dataset (a directory or
``s3://bucket/prefix``) and iterates shuffled action-chunk batches as dicts of numpy
arrays that own the loader's buffers (no copy). Decoding runs on the loader's own Rust
thread pool, batches are prepared ``prefetch`` ahead, and the GIL is released while a
batch is awaited.

``scaledp_data.torch.ScaleDPIterableDataset`` wraps it for ``torch.utils.data.DataLoader``
and DDP; importing ``scaledp_data`` itself never imports torch.
"""

from ._native import DatasetError, Loader, Normalizer, __version__

__all__ = ["DatasetError", "Loader", "Normalizer", "__version__"]
