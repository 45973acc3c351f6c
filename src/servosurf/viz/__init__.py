"""Figures (matplotlib, Agg) and 3-D renders (pyvista), imported lazily.

Nothing here loads a plotting back-end at ``import servosurf``; each function imports
matplotlib or pyvista when called.
"""

from __future__ import annotations

import importlib

_LAZY = {
    "plot_disturbance_frfs": "._servo_plots", "plot_cas": "._servo_plots",
    "plot_rms_vs_bandwidth": "._servo_plots", "plot_error_spectra": "._servo_plots",
    "plot_power_shares": "._servo_plots", "plot_loop_bode": "._servo_plots",
    "plot_tool_frfs": "._servo_plots", "plot_frf_fit": "._servo_plots",
    "plot_map": "._surface_plots", "plot_profile_with_form_error": "._surface_plots",
    "plot_spectrum": "._surface_plots", "plot_filtered_map": "._surface_plots",
    "plot_form_error": "._form_plots", "plot_design_feed": "._form_plots",
    "render_surface": "._render", "RenderFallbackWarning": "._render",
    "surface_to_mesh": "._mesh", "write_mesh": "._mesh",
    "plot_nc_toolpath": "._nc_plots", "plot_band_map": "._nc_plots",
    "plot_centre_profile": "._nc_plots", "plot_roughness_table": "._nc_plots",
    "nc_figures": "._nc_plots",
    "plot_tool_edge": "._edge_plots",
    "plot_profile_overlay": "._profile_plots", "plot_profile_table": "._profile_plots",
    "plot_profile_spectra": "._profile_plots",
    "simulation_figures": "._simulation_plots", "plot_highpass": "._simulation_plots",
    "plot_analysis_spectrum": "._simulation_plots",
    "plot_lenslet_profile": "._simulation_plots",
    "plot_deviation": "._simulation_plots",
    "plot_realisations": "._simulation_plots",
    "plot_map_comparison": "._simulation_plots",
    "diagnosis_figures": "._diagnosis_plots",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'servosurf.viz' has no attribute {name!r}")
