"""Surface figures that do not hang on one realisation: spectra and form error
over many seeds of the vibration.

:func:`lenslet_peak_study` simulates one lenslet toolpath once per seed, takes the
mean spectrum over every seed and every lenslet of the field, finds its peaks,
counts in how many seeds each peak shows on its own, removes the peaks that come
from the controller-rate path samples folding onto the pixel grid (they move when
the pixel pitch changes; physical peaks do not), and takes the median of the form
error over the seeds.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ._simulation import (
    PEAK_FMIN,
    alias_flags,
    analyse,
    lenslet_spectrum,
    path_alias_bands,
)

__all__ = ["lenslet_peak_study", "PEAK_MATCH", "ALIAS_PITCH_FACTOR"]

#: A seed's (or the other pitch's) peak matches a mean-spectrum peak within this
#: relative distance (or two frequency bins, whichever is larger).
PEAK_MATCH = 0.03
#: Pixel pitch of the alias test relative to the field's (0.55 -> 0.60 um): it
#: moves the path-sample fold of the 5 um lenslets from 721 to 268 mm^-1 and that of
#: the 10 um lenslets from 215 to 88 mm^-1 (a pitch of 0.50 um would move the first
#: by 1 % only).
ALIAS_PITCH_FACTOR = 12.0 / 11.0


def _peaks(freq, psd, *, speed=None, n=8):
    from ..metrology import find_peaks_spectrum

    return find_peaks_spectrum(freq, psd, n=n, fmin=PEAK_FMIN, speed=speed)


def _matches(f: float, others: list[float], df: float) -> bool:
    tol = max(2.0 * df, PEAK_MATCH * f)
    return any(abs(g - f) <= tol for g in others)


def lenslet_peak_study(
    toolpath,
    *,
    seeds,
    alias_seeds: int = 6,
    n_peaks: int = 6,
    progress=None,
    **kwargs,
) -> dict[str, Any]:
    """Spectral peaks and form error of a lenslet toolpath over many seeds.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        A lenslet toolpath.
    seeds : sequence of int
        Seeds of the vibration realisation (at least 20 for the paper's rows).
    alias_seeds : int, default: 6
        Seeds simulated again on a pixel grid of ``ALIAS_PITCH_FACTOR`` times the
        pitch along the cut, for the alias test.
    n_peaks : int, default: 6
        Peaks of the mean spectrum reported.
    progress : callable, optional
        Wraps the iterable of seeds.
    **kwargs
        Passed to :func:`servosurf.simulation.simulate` (machine, bandwidth, mass,
        ...).

    Returns
    -------
    dict
        ``seeds``; ``lenslets`` (lenslets per map in the spectrum); ``speed_m_per_s``;
        ``peaks``: per mean-spectrum peak ``freq_per_m`` (1/m), ``temporal_freq_hz``
        (Hz), ``psd_m3``, ``amplitude_m``, ``seed_fraction`` (share of seeds whose
        own spectrum has the peak),
        ``alias`` (it moves when the pixel pitch changes: a fold onto the pixel
        grid, not a surface frequency), ``alias_kind`` (path samples of harmonic k
        when inside :func:`path_alias_bands`, else vibration content above the pixel
        Nyquist frequency) and ``in_sampling_band``; ``physical_peaks_per_m``
        (the non-alias peaks, strongest first); ``alias_bands``; ``form``: the
        median over seeds of each form-error summary (m) and the fraction of seeds
        in which the central maximum lags, per registration and reference.
    """
    from ..simulation import simulate
    from ..toolpath import ToolpathSpec, load_toolpath

    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    seeds = [int(s) for s in seeds]
    psds, seed_peaks, forms = [], [], []
    blocks = None
    it = progress(seeds) if progress is not None else seeds
    first = None
    for seed in it:
        res = simulate(spec, seed=seed, **kwargs)
        a = analyse(res)
        freq, psd, used = lenslet_spectrum(res.surface, blocks=blocks)
        if blocks is None:
            blocks, first = used, (res, a)
        psds.append(psd)
        seed_peaks.append([p["freq_per_m"] for p in _peaks(freq, psd)])
        forms.append(a["form_error_registrations"])
    res0, a0 = first
    speed = a0["surface_speed_m_per_s"]
    mean = np.mean(psds, axis=0)
    df = float(freq[1] - freq[0])
    bands = path_alias_bands(res0, blocks, res0.surface.dy)
    peaks = alias_flags(_peaks(freq, mean, speed=speed), bands, df)
    # alias test: the same seeds on another pixel pitch along the cut
    fld = spec.field
    other = dataclasses.replace(
        spec,
        field=dataclasses.replace(
            fld,
            pitch_y=fld.pitch_y * ALIAS_PITCH_FACTOR,
            ny=int(round(fld.ny / ALIAS_PITCH_FACTOR)),
        ),
    )
    opsds, oblocks = [], None
    for seed in seeds[:alias_seeds]:
        r = simulate(other, seed=seed, **kwargs)
        f2, p2, u2 = lenslet_spectrum(r.surface, blocks=oblocks)
        oblocks = oblocks or u2
        opsds.append(p2)
    other_peaks = (
        [p["freq_per_m"] for p in _peaks(f2, np.mean(opsds, axis=0), n=12)]
        if opsds
        else []
    )
    out_peaks = []
    for rank, pk in enumerate(peaks[:n_peaks]):
        f = pk["freq_per_m"]
        moves = bool(opsds) and not _matches(f, other_peaks, df)
        out_peaks.append(
            {
                "rank": rank + 1,
                "freq_per_m": f,
                "temporal_freq_hz": f * speed,
                "psd_m3": pk["psd_m3"],
                "amplitude_m": pk["amplitude_m"],
                "seed_fraction": float(
                    np.mean([_matches(f, sp, df) for sp in seed_peaks])
                ),
                "alias": moves,
                "alias_kind": (
                    None
                    if not moves
                    else f"path samples, harmonic {pk['alias_harmonic']}"
                    if pk["possible_alias"]
                    else "vibration above the pixel Nyquist frequency"
                ),
                "in_sampling_band": pk["possible_alias"],
            }
        )
    form: dict[str, Any] = {}
    for key in forms[0]:
        vals = {k: [f[key][k] for f in forms] for k in forms[0][key]}
        form[key] = {k: float(np.median(v)) for k, v in vals.items()}
        form[key]["lag_fraction"] = float(
            np.mean([v > 0 for v in vals["lag_central_m"]])
        )
    return {
        "seeds": seeds,
        "alias_test_seeds": seeds[:alias_seeds],
        "lenslets": len(blocks),
        "speed_m_per_s": speed,
        "frequency_resolution_per_m": df,
        "peaks": out_peaks,
        "physical_peaks_per_m": [p["freq_per_m"] for p in out_peaks if not p["alias"]],
        "alias_bands": bands,
        "form": form,
        "air_cut_amplitude_m": a0["air_cut_amplitude_m"],
        "paper_reference_amplitude_m": a0["paper_reference_amplitude_m"],
        "deviation": {
            k: a0[k]
            for k in ("deviation_max_m", "deviation_overshoot_m", "deviation_lag_s",
                      "deviation_lag_deepest_s", "force_max_n")
            if k in a0
        },
    }
