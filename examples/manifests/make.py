"""Write one example recording of every kind a diagnosis manifest accepts.

    python examples/manifests/make.py [FOLDER]      # default: beside this script

Each recording is made by servosurf's simulator for the seed paper's cutting
set-up (built-in machine, 1448 Hz open-loop crossover, 0.175 kg, the 5 um
lenslet toolpath), in the file format and with the conventions a real recording
must follow (see README.md here). The manifests in this folder name them; with
the recordings written, ``servosurf diagnose examples/manifests/<kind>.toml``
diagnoses each (the verdict on these simulated recordings should be
"consistent": each is a null test of one channel). To diagnose a real machine,
put its recording in place of the example's and keep the manifest.

Recordings (SI units, names carry the unit):

* ``idle.npz``: 32 records of 4096 following-error samples at the controller
  rate (199.6 kHz), the tool out of cut (the seed paper's CAS records);
* ``frf_open_loop.csv``, ``frf_closed_loop.csv``, ``frf_force.csv``: 300
  frequencies from 50 Hz to 40 kHz;
* ``cut.csv``: force and following error while cutting the first 20 ms of the
  lenslet toolpath, time from the start of the toolpath (loop at rest at t = 0);
* ``surface/surface.datx`` and ``surface/manifest.toml``: what ``servosurf
  simulate`` writes;
* ``profile.npz``: the map's centre column along the cut (z, dx, x0).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from servosurf.cli import main as servosurf
from servosurf.noise import realise
from servosurf.servo import ServoLoop, load_machine
from servosurf.simulation import simulate
from servosurf.toolpath import builtin_toolpaths

BANDWIDTH = 1448.0  # Hz, the paper's cutting set-up
MASS = 0.175  # kg
SEED = 7


def _csv(path: Path, header: list[str], columns: list[np.ndarray]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in zip(*columns, strict=True):
            w.writerow([repr(float(v)) for v in row])


#: The recordings make.py writes, by group.
GROUPS = ("idle", "frf", "surface", "cut")


def write_all(folder: Path, groups=GROUPS) -> list[Path]:
    """Write the example recordings of ``groups`` into ``folder``; return the files.

    Groups: ``idle`` (idle.npz), ``frf`` (the three FRF CSVs), ``surface``
    (surface/ from servosurf simulate), ``cut`` (cut.csv, profile.npz and
    profile.toml).
    """
    folder.mkdir(parents=True, exist_ok=True)
    machine = load_machine().with_moving_mass(MASS).with_bandwidth(BANDWIDTH)
    loop = ServoLoop(machine)
    files = []
    if "idle" in groups:  # following error, tool out of cut: 32 x 4096 samples
        files += _idle(loop, folder)
    if "frf" in groups:
        files += _frfs(loop, folder)
    if "surface" in groups:
        files += _surface(folder)
    if "cut" in groups:
        files += _cut(loop, folder)
    return files


def _idle(loop, folder):
    files = []
    rec = realise(loop, 32 * 4096, seed=SEED)
    fe = np.asarray(rec.following, dtype=float)[: 32 * 4096].reshape(32, 4096)
    np.savez(folder / "idle.npz", following_error_m=fe, fs_hz=loop.fs)
    files.append(folder / "idle.npz")
    return files


def _frfs(loop, folder):  # frequency responses as a controller measures them
    files = []
    f = np.geomspace(50.0, 40e3, 300)
    frf = loop.frf(f)
    for name, h in (
        ("frf_open_loop.csv", loop.open_loop(f)),  # DAC V -> sensor V, ZOH+delay in
        ("frf_closed_loop.csv", frf.paths[("reference", "sensor")]),  # m/m
        ("frf_force.csv", frf.paths[("force", "sensor")]),  # m/N
    ):
        _csv(folder / name, ["frequency_hz", "real", "imag"], [f, h.real, h.imag])
        files.append(folder / name)
    return files


def _surface(folder):  # the surface and its manifest, as servosurf simulate writes
    sim = folder / "surface"
    assert servosurf(["-q", "simulate", "lenslet_5um", "--seed", str(SEED),
                      "--no-render", "--out", str(sim), "--force"]) == 0
    return [sim / "surface.datx", sim / "manifest.toml"]


def _cut(loop, folder):  # a cut record and a profile of one simulation
    files = []
    res = simulate(builtin_toolpaths()["lenslet_5um"], bandwidth=BANDWIDTH,
                   mass=MASS, seed=SEED, instrument=None)
    n = int(round(0.02 * loop.fs))
    _csv(folder / "cut.csv", ["time_s", "force_n", "following_error_m"],
         [res.t[:n], res.force[:n], res.following_error[:n]])
    files.append(folder / "cut.csv")
    s = res.surface
    xs, ys = s.coords()
    j = s.shape[1] // 2
    np.savez(folder / "profile.npz", z=s.z[:, j], dx=s.dy, x0=ys[0])
    (folder / "profile.toml").write_text(PROFILE_MANIFEST.format(x=float(xs[j])))
    files += [folder / "profile.npz", folder / "profile.toml"]
    return files


#: The profile's manifest (written with the profile: its line passes through the
#: map's centre column, whose x this script knows).
PROFILE_MANIFEST = """\
# Example manifest: one profile of the 5 um lenslet map along the cut (+y) at the
# map's centre column (written by examples/manifests/make.py), then
#   servosurf diagnose examples/manifests/profile.toml
# Conventions of the recording: README.md in this folder.
[case]
machine = "seed-prototype"
toolpath = "lenslet_5um"
bandwidth = 1448.0           # Hz, open-loop crossover
moving-mass = 0.175          # kg, m1 + m2

[[recording]]
path = "profile.npz"         # z (m), dx (m), x0 (m, position of z[0] along the line)
kind = "profile"
start = [{x!r}, 0.0]  # m, the line's origin in the workpiece frame
direction = 1.5707963267948966  # rad, along +y (the cutting direction here)
"""


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent
    for p in write_all(out):
        print(p)
