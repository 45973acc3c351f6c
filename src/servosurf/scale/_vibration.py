"""PSD-shaped vibration for whole-face runs, read by global sample number."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError

__all__ = ["MemmapDeviation", "write_vibration"]


def write_vibration(
    loop, path: str | Path, n: int, *, seed: int, progress=None
) -> Path:
    """Realise ``n`` samples of the loop's real positioning error into ``path``.

    Uses :class:`servosurf.noise.VibrationStream` (block-seeded, bounded memory) and
    stores float32 metres in a ``.npy`` file that tiles memory-map.

    Returns
    -------
    Path
        The file written.
    """
    from ..noise import VibrationStream

    VibrationStream(loop, seed=seed).to_memmap(path, int(n), progress=progress)
    return Path(path)


@dataclass(frozen=True)
class MemmapDeviation:
    """``deviation(path) -> dz`` (m) that looks samples up in a ``.npy`` series.

    Picklable (holds the file name only), so dask workers open the file themselves.

    Parameters
    ----------
    file : str
        ``.npy`` float32 series of the tool-height deviation, sample k at t = k / fs.
    """

    file: str

    def __call__(self, path) -> np.ndarray:
        """Deviation in m for each sample of ``path`` (by ``path.index``)."""
        series = np.load(self.file, mmap_mode="r")
        idx = path.index
        if idx.size and (idx.min() < 0 or idx.max() >= series.size):
            raise ConfigError(
                f"vibration series {self.file} holds {series.size} samples; the path "
                f"needs sample {int(idx.max())}"
            )
        return np.asarray(series[idx], dtype=np.float64)
