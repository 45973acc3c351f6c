"""The diagnosis simulator: the seed-paper loop with pluggable effect modules.

A :class:`~servosurf.diagnose.effects.Model` holds the terms of catalogue effects
(``Model()`` is the nominal machine); each term is a hook of the protocol of
:func:`servosurf.simulation.simulate`, composed here by the same functions
(:mod:`servosurf._hooks`). :class:`CaseModel` evaluates one case (machine,
bandwidth, moving mass, toolpath) under a model:

* frequency domain (sampled-data approximation, as :meth:`ServoLoop.frf`): open-
  and closed-loop FRFs and the stochastic following-error and tool-error PSDs,
  with an extra structural mode and an extra loop delay;
* time domain (exact ZOH discretisation, as :meth:`ServoLoop.simulate`): the loop
  with the memoryless nonlinear modules (current saturation, force constant
  ``Kf(x)``, flexure ``k2q d^2 + k3 d^3``), the extra mode and the chip force.

Decisions (documented here once):

* The controller gains are those tuned for the **nominal** machine at the case's
  bandwidth and are held fixed whatever the effects do to the plant: the
  controller is what was installed, the plant is what is found.
* The structural mode ``q'' + 2 zeta w q' + w^2 q = w^2 g Fa`` is driven by the
  actuator force and adds ``q`` to both the tool and the measured position
  (collocated, ``g > 0``).
* Saturation clips the current demand ``G_I u`` at ``+-I_max`` before the
  amplifier's double pole.
* The flexure nonlinearity acts on m2 only (its reaction on the 1.2 kg, 5e7 N/m
  carriage moves it by picometres).
"""

from __future__ import annotations

import math

import numpy as np

from .. import _hooks
from ..servo import (
    PIDF,
    LoopPerturbation,
    Machine,
    Nonlinearity,
    ServoLoop,
)
from .effects._base import Model

__all__ = ["CaseModel", "NOMINAL"]


NOMINAL = Model()

#: Output names of :meth:`ServoLoop.frf` as the diagnosis calls them.
_OUT = {"following_error": "fe"}


class CaseModel:
    """One diagnosis case: nominal machine, fixed controller and toolpath.

    Parameters
    ----------
    machine : Machine
        Nominal machine (moving mass and bandwidth already applied).
    toolpath : ToolpathSpec, optional
        The toolpath of cut recordings and surface maps.
    specific_force : float, optional
        Nominal specific thrust pressure k_t in N/m^2 (thrust per chip area);
        default the built-in NiP workpiece's
        (:class:`servosurf.cutting.Material`).
    """

    def __init__(
        self, machine: Machine, toolpath=None, *, specific_force: float | None = None
    ) -> None:
        import dataclasses

        from ..cutting import load_workpiece

        wp = load_workpiece(None)
        if specific_force is None:
            specific_force = wp.material.specific_thrust_pressure
        #: the workpiece the model's ``workpiece`` hooks change (its thrust pressure
        #: is the case's)
        self.workpiece = dataclasses.replace(wp, material=dataclasses.replace(
            wp.material, specific_thrust_pressure=float(specific_force)))
        self.machine = machine
        self.toolpath = toolpath
        self.specific_force = float(specific_force)
        self.loop = ServoLoop(machine)
        self.pidf: PIDF = self.loop.pidf
        self.fs = float(machine.controller.sample_rate)
        #: pre-cut height in m the surface model clips at: the flat face at 0, no
        #: material limit (+inf) for an NC program (as
        #: :func:`servosurf.simulation.simulate` sweeps it)
        self.top = (math.inf if toolpath is not None and toolpath.kind == "nc"
                    else 0.0)
        self._cache: dict = {}

    # ------------------------------------------------------------ hooks
    def perturbation(self, model: Model) -> LoopPerturbation:
        """The linear plant change of ``model`` (its ``perturbation`` hooks)."""
        pert = _hooks.compose_perturbation(model.hooks("perturbation"))
        return LoopPerturbation() if pert is None else pert

    def nonlinearity(self, model: Model) -> Nonlinearity:
        """The loop nonlinearities of ``model`` (its ``nonlinearity`` hooks)."""
        nl = _hooks.compose_nonlinearity(model.hooks("nonlinearity"))
        return Nonlinearity() if nl is None else nl

    def base_lines(self, model: Model) -> tuple[tuple[float, float], ...]:
        """Base-vibration lines of ``model``: ``(frequency in Hz, amplitude in m)``."""
        return _hooks.compose_base_lines(model.hooks("base_lines"))

    def sensor_lines(self, model: Model) -> tuple[tuple[float, float], ...]:
        """Sensor pickup lines of ``model`` (logged following error only):
        ``(frequency in Hz, amplitude in m)``."""
        return _hooks.compose_sensor_lines(model.hooks("sensor_lines"))

    def hooked_machine(self, model: Model) -> Machine:
        """The installed machine through ``model``'s ``machine`` hooks (the
        diagnosis reads its disturbance PSDs)."""
        return _hooks.apply_hooks(model.hooks("machine"), "machine", self.machine)

    def path_z(self, model: Model, t, theta, r, z):
        """Outside-the-loop tool-height terms of ``model`` in m (None: none)."""
        return _hooks.compose_path_z(model.hooks("path_z"), t, theta, r, z)

    def edge(self, model: Model, phi: np.ndarray, t: np.ndarray | None = None):
        """The tool terms of ``model`` at contact angles ``phi`` (rad): nose radius
        change in m and outward edge deviation in m (None: none). With the pass
        times ``t`` (s), a term with an ``edge_at(t, phi)`` hook (a tool changing
        in time, e.g. wear) is evaluated at them."""
        d_r = 0.0
        dev = None
        for h in model.hooks("tool"):
            if t is not None and hasattr(h, "edge_at"):
                dr_h, w = h.edge_at(t, phi)
            else:
                dr_h, w = h.edge(phi)
            d_r += dr_h
            if w is not None:
                dev = w if dev is None else dev + w
        return d_r, dev

    def min_chip_thickness(self, model: Model) -> float:
        """Minimum chip thickness h_min in m of ``model``'s ``cutting_rules`` hooks
        (0: every pass that reaches a point cuts it, the kinematic envelope).

        Raises
        ------
        ConfigError
            When a hook sets a rule the pointwise model does not evaluate (side
            flow, recovery of the ordered sweep).
        """
        hooks = model.hooks("cutting_rules")
        if not hooks:
            return 0.0
        from ..errors import ConfigError
        from ..toolpath import CuttingRules

        rules = _hooks.apply_hooks(hooks, "cutting_rules", CuttingRules())
        if (rules.side_flow_height or rules.side_flow_width or rules.recovery_height
                or rules.recovery_decay):
            raise ConfigError("the diagnosis's surface model evaluates the minimum "
                              "chip thickness only (allowed: side flow and recovery "
                              "rules of 0)")
        return float(rules.min_chip_thickness)

    def surface_heights(self, model: Model, z: np.ndarray, top: float) -> np.ndarray:
        """Point heights ``z`` (m) through ``model``'s surface terms (pre-cut
        height ``top`` in m)."""
        for h in model.hooks("surface"):
            z = h.surface_heights(z, top)
        return z

    # ------------------------------------------------------------ machine
    def loop_for(self, p: Model) -> ServoLoop:
        """The simulator's loop under ``p`` with the installed (nominal) controller."""
        return self.loop.perturbed(self.perturbation(p))

    def machine_for(self, p: Model) -> Machine:
        """Machine with the recalibration and delay knobs of ``p`` applied."""
        return self.loop_for(p).machine

    def tool_radius(self) -> float:
        """Nose radius of the case's tool in m (0.5 mm without a toolpath)."""
        return (
            float(self.toolpath.tool.nose_radius)
            if self.toolpath is not None
            else 0.5e-3
        )

    # ------------------------------------------------------------ frequency
    def paths(self, p: Model, freq: np.ndarray) -> dict:
        """Closed-loop and open-loop responses at ``freq`` (Hz) under ``p``.

        The simulator's own FRFs (:meth:`ServoLoop.frf` and
        :meth:`ServoLoop.open_loop` under :meth:`perturbation`), renamed for the
        diagnosis.

        Returns
        -------
        dict
            ``"open_loop"``: DAC V -> sensor V (ZOH and delay included);
            ``"loop"``: the open-loop gain L;
            ``(input, output)`` for inputs ``reference``, ``sensor_noise``,
            ``current_noise`` (per A), ``base`` (per m), ``force`` (per N) and
            outputs ``fe`` (following error, m), ``tool`` (m), ``sensor`` (m).
        """
        freq = np.asarray(freq, dtype=float)
        pert = self.perturbation(p)
        frf = self.loop.frf(freq, perturbation=pert)
        out: dict = {
            "open_loop": self.loop.open_loop(freq, perturbation=pert),
            "loop": frf.loop,
        }
        for (inp, outp), h in frf.paths.items():
            out[(inp, _OUT.get(outp, outp))] = h
        return out

    def disturbance_psds(self, p: Model, freq: np.ndarray) -> dict:
        """Disturbance PSDs Ws (m^2/Hz), Wi (A^2/Hz), Wg (m^2/Hz) under ``p``."""
        from ..noise import evaluate_psd

        d = self.hooked_machine(p).disturbances
        return {
            "sensor_noise": evaluate_psd(d.sensor_noise, freq),
            "current_noise": evaluate_psd(d.current_noise, freq),
            "base": evaluate_psd(d.base_vibration, freq),
        }

    def noise_psd(
        self,
        p: Model,
        freq: np.ndarray,
        output: str = "fe",
        paths: dict | None = None,
    ) -> np.ndarray:
        """One-sided PSD (m^2/Hz) of the stochastic part of ``output`` at ``freq``.

        ``output`` is ``"fe"`` (following error) or ``"tool"`` (real tool error).
        Frequencies below ``fs / 4096`` carry no power (the project's convention,
        :func:`servosurf.noise.frequency_grid`). Lines are not included.
        """
        parts = self.noise_psd_sources(p, freq, output, paths)
        return sum(parts.values(), np.zeros(np.shape(freq)))

    def noise_psd_sources(
        self,
        p: Model,
        freq: np.ndarray,
        output: str = "fe",
        paths: dict | None = None,
    ) -> dict[str, np.ndarray]:
        """:meth:`noise_psd` split by source (``sensor_noise``, ``current_noise``,
        ``base``): each source's one-sided PSD (m^2/Hz) at ``output``."""
        freq = np.asarray(freq, dtype=float)
        ps = self.paths(p, freq) if paths is None else paths
        w = self.disturbance_psds(p, freq)
        low = freq < self.fs / 4096 * (1 - 1e-9)
        out = {}
        for name, wk in w.items():
            part = wk * np.abs(ps[(name, output)]) ** 2
            part[low] = 0.0
            out[name] = part
        return out

    # ------------------------------------------------------------ time domain
    def discrete(self, p: Model):
        """Discrete model ``(ad, bd, cx, nd, frac)`` of the loop under ``p``."""
        lp = self.loop_for(p)
        ad, bd, cx = lp.discrete_models()[:3]
        nd, frac = lp.delay_split()
        return ad, bd, cx, nd, frac

    def controller(self):
        """Tustin controller ``(ac, bc, cc, dc)`` of the installed PIDF."""
        ac, bc, cc, dc = self.loop.discrete_models()[3:]
        return ac, bc, np.ascontiguousarray(cc.ravel()), float(dc.ravel()[0])

    def kt(self, p: Model) -> float:
        """Specific thrust pressure under ``p`` in N/m^2 (its ``workpiece`` hooks)."""
        hooks = p.hooks("workpiece")
        if not hooks:
            return self.specific_force
        return float(_hooks.apply_hooks(hooks, "workpiece", self.workpiece)
                     .material.specific_thrust_pressure)

    def facing_force(self, p: Model, t: np.ndarray) -> np.ndarray:
        """Steady facing thrust ``k_t A`` (N), ramped in over the first revolution.

        As :func:`servosurf.simulation.simulate`: the feed-limited chip section of
        :func:`servosurf.cutting.facing_chip_area`, ramped from the record's start.
        """
        from ..cutting import facing_chip_area

        path = self.toolpath.path
        key = ("facing_area",)
        if key not in self._cache:
            self._cache[key] = facing_chip_area(
                self.tool_radius(), path.feed_per_rev, path.depth_of_cut
            )
        ramp = np.clip((t - t[0]) * path.rev_per_s, 0.0, 1.0)
        return self.kt(p) * self._cache[key] * ramp

    def simulate_path(self, p: Model, t: np.ndarray) -> dict[str, np.ndarray]:
        """Cut the case's toolpath at times ``t`` (s), loop at rest at ``t[0]``.

        Lenslets: the chip force of a round tool plunging into the flat face at
        z = 0, from the actual tool height; facing: the steady feed-limited chip
        force (see :meth:`facing_force`); design surfaces: the finishing pass's
        facing chip at the local feed (:func:`servosurf.simulation.design_force`);
        NC programs: no chip force (simulate's parts for an NC program on the FTS
        are tracking and vibration).
        """
        spec = self.toolpath
        t = np.asarray(t, dtype=float)
        # the command (a design path's nose-compensated tip heights are costly)
        # and the unit-pressure design force are the same for every model
        key = ("command", float(t[0]), int(t.size), float(t[-1]))
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            self._cache[key] = spec.path.z_at(t)
        ref = self._cache[key]
        if spec.kind == "facing":
            return self.simulate(p, reference=ref, force=self.facing_force(p, t))
        if spec.kind == "surface":
            from ..simulation import design_force

            fkey = ("design_force",) + key[1:]
            if fkey not in self._cache:
                self._cache[fkey] = design_force(spec.path, spec.tool, 1.0, t)
            return self.simulate(p, reference=ref, force=self.kt(p) * self._cache[fkey])
        if spec.kind == "nc":
            return self.simulate(p, reference=ref)
        return self.simulate(p, reference=ref, chip=True)

    def simulate(
        self,
        p: Model,
        *,
        reference: np.ndarray,
        force: np.ndarray | None = None,
        chip: bool = False,
        current_noise: np.ndarray | None = None,
        sensor_noise: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """Simulate the loop sample by sample under ``p``.

        Parameters
        ----------
        p : Model
            Effects.
        reference : ndarray of shape (n,)
            Commanded tool height in m (loop at rest before the first sample).
        force : ndarray of shape (n,), optional
            External force on the tool in N.
        chip : bool, default: False
            Add the chip force of the case's toolpath, computed from the actual
            tool height.
        current_noise, sensor_noise : ndarray of shape (n,), optional
            Noise inputs in A and m.

        Returns
        -------
        dict of str to ndarray of shape (n,)
            ``tool`` (m), ``sensor`` (m), ``fe`` (m), ``u`` (V), ``force`` (N),
            ``current`` (A). Non-finite values mean the loop diverged.
        """
        from ..cutting import ChipModel

        chip_model = ChipModel(self.kt(p), self.tool_radius(), 0.0) if chip else None
        out = self.loop.simulate(
            reference=reference,
            force=force,
            current_noise=current_noise,
            sensor_noise=sensor_noise,
            chip=chip_model,
            perturbation=self.perturbation(p),
            nonlinearity=self.nonlinearity(p),
        )
        return {
            "tool": out["tool"],
            "sensor": out["sensor"],
            "fe": out["following_error"],
            "u": out["u"],
            "force": out["force"],
            "current": out["current"],
        }

    # ------------------------------------------------------------ stability
    def is_stable(self, p: Model) -> bool:
        """True when the discrete closed loop under ``p`` is stable (linear part)."""
        return self.loop.is_stable(perturbation=self.perturbation(p))
