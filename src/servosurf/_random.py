"""Independent random streams from one user seed: every generator starts here.

Every stochastic part of a simulation draws from its own stream of the user's
seed, so that no two parts share normal numbers (``tests/test_architecture.py``
checks that no other module starts a generator):

* the vibration realisation (:func:`servosurf.noise.realise`) draws from the root
  stream, :func:`root` = ``default_rng(seed)`` (kept from earlier versions: seeded
  results do not move);
* the interferometer's height noise and dropouts draw from child 1 of
  ``SeedSequence(seed)`` (:func:`stream` ``"instrument"``), i.e.
  ``SeedSequence(seed).spawn(2)[1]``;
* the spindle's asynchronous axial error draws from the keyed pool
  ``default_rng([seed, 0x5B1D])`` (:func:`keyed` ``"spindle"``), an independent
  entropy pool (kept from earlier versions);
* the block-seeded vibration stream of whole faces draws block ``b`` from
  ``default_rng([seed, b])`` (:func:`block`; the same samples whatever the
  tiling). numpy's ``SeedSequence`` drops trailing zero words, so block 0 is the
  root stream: a face run draws only blocks and :func:`~servosurf.simulation.
  simulate` only the root, so the two never meet in one run (kept so that seeded
  faces do not move);
* figures draw their jitter from :func:`figure_jitter` (seed 0: the same figure
  every time; no result depends on it).

Add a new part as the next child of :data:`STREAMS`, never by reusing a seed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STREAMS", "KEYS", "stream", "root", "keyed", "block", "figure_jitter"]

#: Child index of each named stream of ``SeedSequence(seed)``.
STREAMS = {"instrument": 1}

#: Second entropy word of each keyed pool ``default_rng([seed, key])``.
KEYS = {"spindle": 0x5B1D}


def root(seed: int) -> np.random.Generator:
    """The root stream ``default_rng(seed)``: the vibration realisation's.

    Parameters
    ----------
    seed : int
        The user's seed (>= 0).

    Returns
    -------
    numpy.random.Generator
        A new generator.
    """
    return np.random.default_rng(seed)


def stream(seed: int, name: str) -> np.random.Generator:
    """The generator of child stream ``name`` for a user ``seed`` (>= 0).

    ``SeedSequence(seed, spawn_key=(k,))`` is the k-th child that
    ``SeedSequence(seed).spawn`` returns, independent of the root stream.

    Parameters
    ----------
    seed : int
        The user's seed (>= 0).
    name : str
        A key of :data:`STREAMS`.

    Returns
    -------
    numpy.random.Generator
        A new generator.
    """
    return np.random.default_rng(
        np.random.SeedSequence(int(seed), spawn_key=(STREAMS[name],)))


def keyed(seed: int, name: str) -> np.random.Generator:
    """The keyed pool ``default_rng([seed, KEYS[name]])`` for a user ``seed``.

    Parameters
    ----------
    seed : int
        The user's seed (>= 0).
    name : str
        A key of :data:`KEYS`.

    Returns
    -------
    numpy.random.Generator
        A new generator.
    """
    return np.random.default_rng([int(seed), KEYS[name]])


def block(seed: int, index: int) -> np.random.Generator:
    """Block ``index`` of the block-seeded vibration stream, ``default_rng([seed, b])``.

    Parameters
    ----------
    seed : int
        The user's seed (>= 0).
    index : int
        Block index (>= 0).

    Returns
    -------
    numpy.random.Generator
        A new generator.
    """
    return np.random.default_rng([int(seed), int(index)])


def figure_jitter() -> np.random.Generator:
    """A fixed generator for the jitter of figure markers (the same figure each run).

    Returns
    -------
    numpy.random.Generator
        ``default_rng(0)``.
    """
    return np.random.default_rng(0)
