"""Surface metrology: the Surface type, filters, roughness, spectra, form error."""

from ._surface import Profile, Surface

__all__ = ["Surface", "Profile"]
