"""Discrepancy discovery: locate, explain and refit what the model leaves out.

``servosurf diagnose MANIFEST.toml`` compares recordings (following error, FRFs,
cuts, surface maps, profiles) with the simulator, locates where and how surely they
differ, ranks a catalogue of left-out physics by how well each module's signature
matches, fits the best under a BIC-like criterion, and says ``unexplained`` when no
module accounts for the mismatch. See ``/work/shared/DISCOVERY.md`` for the design,
:mod:`servosurf.diagnose._diagnose` for the pipeline and
:mod:`servosurf.diagnose.effects` for the catalogue (one module per effect).
"""

from ._diagnose import VERDICTS, Diagnosis, build_case, diagnose
from ._locate import Mismatch, gather, locate
from ._manifest import (
    DIAGNOSABLE_TOOLPATHS,
    KINDS,
    CaseTable,
    Manifest,
    Recording,
    RecordingTable,
    load_manifest,
    read_recording,
    simulation_manifest,
)
from ._report import (
    figure_data,
    fitted_effects_toml,
    fitted_machine_toml,
    write_figures,
)
from ._sim import CaseModel
from .effects import (
    CATALOGUE,
    Effect,
    EffectParams,
    Evidence,
    Model,
    catalogue_table,
    get_effect,
)

__all__ = [
    "CATALOGUE",
    "Effect",
    "EffectParams",
    "Evidence",
    "Model",
    "catalogue_table",
    "get_effect",
    "VERDICTS",
    "Diagnosis",
    "build_case",
    "diagnose",
    "Mismatch",
    "gather",
    "locate",
    "DIAGNOSABLE_TOOLPATHS",
    "KINDS",
    "CaseTable",
    "Manifest",
    "Recording",
    "RecordingTable",
    "load_manifest",
    "read_recording",
    "simulation_manifest",
    "figure_data",
    "fitted_effects_toml",
    "fitted_machine_toml",
    "write_figures",
    "CaseModel",
]
