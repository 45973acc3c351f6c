"""DAC/ADC quantisation and a command dead band (DISCOVERY.md catalogue row 15)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ._base import Config, Effect, EffectParams, Free, quantity

__all__ = ["ConverterQuantisationParams", "ConverterQuantisationEffect"]

NAME = "converter-quantisation"

#: Coarsest DAC step: a 12-bit converter over +-10 V, in V.
MAX_DAC_STEP = 20.0 / 2**12
#: Coarsest ADC step referred to position: 12 bits over a 100 um gauge range, m.
MAX_ADC_STEP = 100e-6 / 2**12
#: Largest dead band of the command, in V.
MAX_DEAD_BAND = 0.02
#: Search ranges start this far below the largest values (log scale).
SPAN = 1e-4

_DAC_SOURCE = (
    "at most the step of a 12-bit DAC over +-10 V (4.9 mV); servo DACs are "
    "16-20 bit (0.3 mV to 19 uV), e.g. dSPACE DS2102 (16 bit, +-10 V) or "
    "AD5791 (20 bit)")
_ADC_SOURCE = (
    "at most a 12-bit conversion of a 100 um capacitive-gauge range (24 nm); "
    "gauge electronics digitise with 16-24 bits (Lion Precision CPL190 range "
    "50-250 um, AD7760 24-bit ADC)")
_DEAD_SOURCE = (
    "at most 20 mV (0.1 % of a +-10 V input range): crossover and PWM dead-time "
    "zones of precision servo amplifiers are specified at the mV level")


@dataclass(frozen=True)
class ConverterQuantisationParams(EffectParams):
    """Quantisation of the loop's converters and a dead band of the command.

    The DAC and ADC steps act through their additive-noise equivalent (white,
    variance ``step^2 / 12`` per sample). The DAC's is a current-noise floor
    ``G_I dac_step / sqrt(6 fs)`` in A/sqrt(Hz), added in quadrature to the
    machine file's floor: the DAC drives the current amplifier, whose roll-off
    shapes it. The ADC's is a white sensor-noise density ``adc_step / sqrt(6 fs)``
    in m/sqrt(Hz) added after the sensor noise's roll-off (``PSDModel.white``):
    the ADC digitises the gauge electronics' output, so its rounding is white up
    to the controller's Nyquist frequency, not rolled off at the gauge's corner
    (rolled off, a 0.3-0.8 nm step's noise hid under the model above 15 kHz and
    the excess above 64 kHz stayed unexplained). The dead band is a deterministic nonlinearity of the loop
    (the command ``u`` is zero for ``|u| <= b`` and ``u -+ b`` beyond).
    """

    effect = NAME

    dac_step: float = quantity(
        0.0, unit="V", doc="DAC quantisation step (LSB)", low=0.0,
        high=MAX_DAC_STEP, source=_DAC_SOURCE)
    adc_step: float = quantity(
        0.0, unit="m", doc="ADC quantisation step of the position reading (LSB)",
        low=0.0, high=MAX_ADC_STEP, source=_ADC_SOURCE)
    dead_band: float = quantity(
        0.0, unit="V", doc="dead band of the DAC command", low=0.0,
        high=MAX_DEAD_BAND, source=_DEAD_SOURCE)

    def nonlinearity(self):
        """The loop's dead-band field."""
        return {"dac_dead_band": self.dead_band}

    def machine(self, m):
        """The machine with the converters' quantisation-noise floors added."""
        if self.dac_step == 0.0 and self.adc_step == 0.0:
            return m
        fs = m.controller.sample_rate
        d = m.disturbances
        cn, sn = d.current_noise, d.sensor_noise
        i_q = m.actuator.current_gain * self.dac_step / math.sqrt(6.0 * fs)
        y_q = self.adc_step / math.sqrt(6.0 * fs)
        cn = dataclasses.replace(cn, floor=math.hypot(cn.floor, i_q))
        sn = dataclasses.replace(sn, white=math.hypot(sn.white, y_q))
        return dataclasses.replace(m, disturbances=dataclasses.replace(
            d, current_noise=cn, sensor_noise=sn))


#: Configurations: the field each searches.
_KINDS = ("dac_step", "adc_step", "dead_band")
_LABELS = {"dac_step": "DAC step", "adc_step": "ADC step", "dead_band": "dead band"}
_MAX = {"dac_step": MAX_DAC_STEP, "adc_step": MAX_ADC_STEP, "dead_band": MAX_DEAD_BAND}


class ConverterQuantisationEffect(Effect):
    name = NAME
    title = "Converter quantisation and dead band"
    physics = (
        "Finite resolution of the DAC (command, V) and of the ADC (position "
        "reading, m): white quantisation noise of variance LSB^2 / 12 per "
        "sample; a dead band of the command around zero."
    )
    signature = (
        "Idle following-error spectrum: a white floor rising to the Nyquist "
        "frequency (ADC: not rolled off like the sensor's electronics; DAC: "
        "through the loop's force path); dead band: errors at every zero "
        "crossing of the command, growing at small amplitude."
    )
    confused_with = (
        "sensor-noise-shape (a floor that rolls off at the sensor corner); "
        "friction (errors at velocity, not command, reversals); a level read "
        "from raw-count histograms tells quantisation apart."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = ConverterQuantisationParams

    def _probe(self, kind, ev):
        if kind == "adc_step":
            n = ev.nominal
            return 0.3 * math.sqrt(6.0 * ev.fs) * max(n.sensor_floor, n.sensor_level)
        return 1e-4

    def configs(self, ev, model):
        return [Config(_LABELS[k], {"kind": k}) for k in _KINDS]

    def n_params(self, cfg=None):
        return 1 if cfg is not None else len(_KINDS)

    def _current(self, model):
        ps = model.get(NAME)
        q = ps[0] if ps else ConverterQuantisationParams()
        return {k: getattr(q, k) for k in _KINDS}

    def columns(self, model, cfg, ev):
        k = cfg.values["kind"]
        pr = self._probe(k, ev)
        kw = self._current(model)
        kw[k] = math.hypot(kw[k], pr) if k != "dead_band" else kw[k] + pr
        return [(model.with_terms(NAME, (ConverterQuantisationParams(**kw),)), pr)]

    def start(self, model, cfg, coefs, ev):
        k = cfg.values["kind"]
        pr = self._probe(k, ev)
        c = 1.0 if coefs is None else float(coefs[0])
        lo = SPAN * _MAX[k]
        # the noise columns are linear in the variance, the dead band in itself
        v = pr * math.sqrt(max(c, 0.0)) if k != "dead_band" else pr * c
        kw = dict.fromkeys(_KINDS, 0.0)
        kw[k] = min(max(v, 2 * lo), 0.99 * _MAX[k])
        return model.with_terms(NAME, (ConverterQuantisationParams(**kw),))

    def free(self, model, slot, ev, cfg=None):
        q = self.term(model, slot)
        kinds = (cfg.values["kind"],) if cfg is not None else tuple(
            k for k in _KINDS if getattr(q, k) > 0)
        return [Free(k, NAME, slot, k, SPAN * _MAX[k], _MAX[k], True) for k in kinds]
