"""Type stubs of the extension module (python/src/*.rs)."""

from os import PathLike
from typing import Any, Dict, Iterator, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class DatasetError(RuntimeError): ...

NormName = Literal["min_max", "mean_std", "none"]

class Normalizer:
    @property
    def state_dim(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def state_norm(self) -> NormName: ...
    @property
    def action_norm(self) -> NormName: ...
    @property
    def state_scale(self) -> List[float]: ...
    @property
    def state_offset(self) -> List[float]: ...
    @property
    def action_scale(self) -> List[float]: ...
    @property
    def action_offset(self) -> List[float]: ...
    def normalize_state(self, x: npt.ArrayLike) -> npt.NDArray[np.float32]: ...
    def unnormalize_state(self, x: npt.ArrayLike) -> npt.NDArray[np.float32]: ...
    def normalize_action(self, x: npt.ArrayLike) -> npt.NDArray[np.float32]: ...
    def unnormalize_action(self, x: npt.ArrayLike) -> npt.NDArray[np.float32]: ...

class Loader:
    def __init__(
        self,
        location: Union[str, PathLike[str]],
        *,
        obs_horizon: int = 2,
        action_chunk: int = 16,
        action_offset: int = 0,
        cameras: Optional[Sequence[str]] = None,
        image_size: Optional[Tuple[int, int]] = None,
        drop_first: int = 0,
        drop_last: int = 0,
        split: Literal["all", "train", "val"] = "all",
        val_ratio: float = 0.0,
        split_seed: int = 0,
        max_episodes: Optional[int] = None,
        state_norm: NormName = "mean_std",
        action_norm: NormName = "min_max",
        batch_size: int = 64,
        drop_incomplete_batch: bool = False,
        shuffle: bool = True,
        seed: int = 0,
        rank: int = 0,
        world_size: int = 1,
        threads: int = 0,
        prefetch: int = 2,
        streaming: Optional[int] = None,
        skip_bad_samples: int = 0,
        video_tolerance_s: float = 1e-4,
        video_decoders: int = 0,
    ) -> None: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[Dict[str, np.ndarray]]: ...
    def __next__(self) -> Dict[str, np.ndarray]: ...
    @property
    def num_samples(self) -> int: ...
    @property
    def epoch(self) -> int: ...
    def set_epoch(self, epoch: int) -> None: ...
    def state_dict(self) -> Dict[str, int]: ...
    def load_state_dict(self, state: Dict[str, int]) -> None: ...
    @property
    def normalizer(self) -> Normalizer: ...
    @property
    def info(self) -> Dict[str, Any]: ...
