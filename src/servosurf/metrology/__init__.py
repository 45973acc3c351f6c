"""Surface metrology: the Surface type, filters, roughness, spectra, form error.

Axis convention: rows are y, columns are x (row 0 at the top of the image). All
lengths are in m and spatial frequencies in 1/m.
"""

from ._filters import gaussian_filter_1d, gaussian_filter_2d, high_pass
from ._interferometer import INSTRUMENTS, Interferometer, load_instrument, measure
from ._form import (
    form_error_profile,
    lenslet_centre_profile,
    nominal_lenslet_profile,
    nominal_lenslet_surface,
)
from ._lenslet import find_deepest_point, segment_lenslets
from ._register import register_translation, remove_form, resample, shift_surface
from ._roughness import areal_roughness, iso4288_cutoff, profile_roughness
from ._spectrum import find_peaks_spectrum, psd_1d
from ._surface import Profile, Surface

__all__ = [
    "Surface",
    "Profile",
    # filters (ISO 16610-21, -61)
    "gaussian_filter_1d",
    "gaussian_filter_2d",
    "high_pass",
    # roughness (ISO 4287, 4288, 25178-2)
    "profile_roughness",
    "areal_roughness",
    "iso4288_cutoff",
    # spectra
    "psd_1d",
    "find_peaks_spectrum",
    # lenslet form
    "nominal_lenslet_profile",
    "nominal_lenslet_surface",
    "form_error_profile",
    "lenslet_centre_profile",
    "find_deepest_point",
    "segment_lenslets",
    # registration and resampling
    "register_translation",
    "shift_surface",
    "resample",
    "remove_form",
    # interferometer model
    "Interferometer",
    "INSTRUMENTS",
    "load_instrument",
    "measure",
]
