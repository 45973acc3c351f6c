"""Independent random streams from one user seed.

Every stochastic part of a simulation draws from its own stream of
``numpy.random.SeedSequence(seed)``, so that no two parts share normal numbers:

* the vibration realisation (:func:`servosurf.noise.realise`) draws from the root
  stream ``default_rng(seed)`` (kept from earlier versions: seeded results do not
  move);
* the interferometer's height noise and dropouts draw from child 1,
  ``SeedSequence(seed).spawn(2)[1]``;
* the spindle's asynchronous axial error draws from ``default_rng([seed, 7])``
  (:mod:`servosurf.noise._spindle`), an independent entropy pool.

Add a new part as the next child here, never by reusing a seed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STREAMS", "stream"]

#: Child index of each named stream of ``SeedSequence(seed)``.
STREAMS = {"instrument": 1}


def stream(seed: int, name: str) -> np.random.Generator:
    """The generator of stream ``name`` for a user ``seed`` (>= 0).

    ``SeedSequence(seed, spawn_key=(k,))`` is the k-th child that
    ``SeedSequence(seed).spawn`` returns, independent of the root stream.
    """
    return np.random.default_rng(
        np.random.SeedSequence(int(seed), spawn_key=(STREAMS[name],)))
