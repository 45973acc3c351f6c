"""Surface metrology: the Surface type, filters, roughness, spectra, form error.

Axis convention: rows are y, columns are x; pixel (i, j) is centred at
``(x0 + j dx, y0 + i dy)``. All lengths are in m and spatial frequencies in 1/m.

Only :class:`Surface` and :class:`Profile` load eagerly; the analysis functions
(scipy, scikit-image) load on first use, so reading a file stays quick.
"""

from __future__ import annotations

import importlib

from ._surface import Profile, Surface

_LAZY = {
    # filters (ISO 16610-21, -61)
    "gaussian_filter_1d": "._filters", "gaussian_filter_2d": "._filters",
    "high_pass": "._filters",
    # roughness (ISO 4287, 4288, 25178-2)
    "profile_roughness": "._roughness", "areal_roughness": "._roughness",
    "iso4288_cutoff": "._roughness",
    # ISO 25178-2 field parameters (height, hybrid, spatial, material ratio)
    "areal_parameters": "._areal", "areal_autocorrelation": "._areal",
    # spectra
    "psd_1d": "._spectrum", "find_peaks_spectrum": "._spectrum",
    "sampling_alias_bands": "._spectrum",
    # lenslet form
    "nominal_lenslet_profile": "._form", "nominal_lenslet_surface": "._form",
    "form_error_profile": "._form", "lenslet_centre_profile": "._form",
    # form error against a design surface
    "form_error_against_design": "._design_form", "DesignFormError": "._design_form",
    "find_deepest_point": "._lenslet", "segment_lenslets": "._lenslet",
    # registration and resampling
    "register_translation": "._register", "shift_surface": "._register",
    "resample": "._register", "remove_form": "._register",
    # profiles: crop, line through a map, 1-D registration
    "crop_profile": "._profile", "trim_invalid_ends": "._profile",
    "profile_through": "._profile", "resample_profile": "._profile",
    "register_profiles": "._profile", "ProfileRegistration": "._profile",
    # interferometer model
    "Interferometer": "._interferometer", "INSTRUMENTS": "._interferometer",
    "load_instrument": "._interferometer", "measure": "._interferometer",
}

__all__ = ["Surface", "Profile", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'servosurf.metrology' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
