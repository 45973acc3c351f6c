"""Independent random streams from one seed (servosurf/_random.py)."""

from __future__ import annotations

import numpy as np

from servosurf import _random


def test_root_stream_is_the_seeds_own_generator():
    """The vibration realisation keeps ``default_rng(seed)``: seeded results of
    earlier versions do not move."""
    a = _random.root(5).standard_normal(64)
    b = np.random.default_rng(5).standard_normal(64)
    np.testing.assert_array_equal(a, b)


def test_instrument_stream_is_the_first_spawned_child():
    a = _random.stream(5, "instrument").standard_normal(64)
    child = np.random.SeedSequence(5).spawn(2)[1]
    np.testing.assert_array_equal(a, np.random.default_rng(child).standard_normal(64))


def test_streams_of_one_seed_share_no_numbers():
    n = 4096
    draws = {
        "root": _random.root(3).standard_normal(n),
        "instrument": _random.stream(3, "instrument").standard_normal(n),
        "spindle": _random.keyed(3, "spindle").standard_normal(n),
        "block1": _random.block(3, 1).standard_normal(n),
    }
    names = sorted(draws)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            # independent unit normals: correlation ~ N(0, 1/n), 6 sigma bound
            r = np.corrcoef(draws[a], draws[b])[0, 1]
            assert abs(r) < 6 / np.sqrt(n), (a, b, r)
            assert not np.isin(draws[a], draws[b]).any(), (a, b)


def test_block_zero_is_the_root_stream_as_documented():
    """numpy's SeedSequence drops trailing zero words: block 0 of the face's
    stream is the root stream. The two never meet in one run (a face draws only
    blocks; simulate only the root), which _random's docstring states."""
    np.testing.assert_array_equal(_random.block(3, 0).standard_normal(16),
                                  _random.root(3).standard_normal(16))


def test_keyed_and_block_pools_are_the_documented_entropy():
    np.testing.assert_array_equal(
        _random.keyed(2, "spindle").standard_normal(8),
        np.random.default_rng([2, 0x5B1D]).standard_normal(8))
    np.testing.assert_array_equal(
        _random.block(2, 11).standard_normal(8),
        np.random.default_rng([2, 11]).standard_normal(8))


def test_vibration_and_instrument_noise_draw_different_numbers():
    """The interferometer's noise is not the vibration's draw (issue 16)."""
    from servosurf.metrology import Surface, load_instrument, measure

    z = np.zeros((64, 64))
    surf = Surface(z, 1e-6, 1e-6)
    inst = load_instrument("cp300-20x")
    m1 = measure(surf, inst, seed=9)
    m2 = measure(surf, inst, seed=9)
    np.testing.assert_array_equal(m1.z, m2.z)  # seeded
    noise = m1.z[np.isfinite(m1.z)].ravel()
    root = _random.root(9).standard_normal(noise.size)
    assert abs(np.corrcoef(noise, root)[0, 1]) < 6 / np.sqrt(noise.size)
