"""Disturbance PSDs, frequency-domain error synthesis (Eqs 8-12), realisations,
and the spindle's asynchronous axial error motion."""

from ._psd import (
    PAPER_RECORD_LENGTH,
    PAPER_RECORDS,
    evaluate_psd,
    frequency_grid,
    read_psd_csv,
    welch_psd,
    write_psd_csv,
)
from ._spindle import psd_series, realise_spindle_axial
from ._stream import BLOCK, VibrationStream
from ._study import (
    LOOP_STATES,
    DesignStudy,
    LoopLimit,
    design_study,
    loop_limit,
    loop_state,
    optimal_bandwidth,
    rms_at,
    stability_limit,
    tuning_limit,
)
from ._synthesis import SOURCES, ErrorBudget, Realisation, cas, realise, synthesize

__all__ = [
    "PAPER_RECORD_LENGTH",
    "PAPER_RECORDS",
    "evaluate_psd",
    "frequency_grid",
    "read_psd_csv",
    "welch_psd",
    "write_psd_csv",
    "psd_series",
    "realise_spindle_axial",
    "BLOCK",
    "VibrationStream",
    "DesignStudy",
    "design_study",
    "optimal_bandwidth",
    "rms_at",
    "stability_limit",
    "tuning_limit",
    "loop_limit",
    "loop_state",
    "LoopLimit",
    "LOOP_STATES",
    "SOURCES",
    "ErrorBudget",
    "Realisation",
    "cas",
    "realise",
    "synthesize",
]
