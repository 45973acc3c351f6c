"""The package version, on the ground floor (file writers stamp it)."""

__all__ = ["__version__"]

__version__ = "0.1.0"
