"""Generate the blind discovery benchmark: case folders plus a sealed key.

Usage::

    python benchmarks/discovery/generate.py OUT [--quick] [--seed N] [--jobs 2]

Writes ``OUT/cases/case_NNNN/`` (manifest and recordings only; case numbers are a
seeded shuffle, so the folder name says nothing about the content) and the key:

* ``OUT/key.sealed``: the truth of every case (effects, ENR, parameters), zlib
  compressed and XOR-ed with a SHA-256 counter keystream of a random secret;
* ``OUT/key.secret``: that secret (the scorer reads it only after every diagnosis
  is written);
* ``OUT/key.sha256``: SHA-256 of the plain key, so the scorer can prove the key
  it opens is the one written before the diagnoses ran.

The suite (``--quick`` gives a small subset on the short campaign):

* every catalogue effect x ENR 0.03, 0.1, 0.3 x 5 seeds (random sub-forms and
  off-grid parameters);
* 20 nulls;
* 10 out-of-catalogue cases (Bouc-Wen hysteresis, quadratic damping, Coulomb
  friction, a non-collocated mode of opposite sign, 1/f sensor-noise excess; ENR
  0.3 and 1);
* 10 two-effect cases (ENR 0.1 and 0.3).
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import os
import secrets
import sys
import zlib
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

ENRS = (0.03, 0.1, 0.3)


def suite(quick: bool, seed: int) -> list[dict]:
    """Case specifications in a seeded random order."""
    import cases as C
    import numpy as np

    specs = []
    if quick:
        for e in C.EFFECTS:
            specs.append({"effects": [e], "ool": None, "enr": 0.3})
        specs += [{"effects": [], "ool": None, "enr": 0.0} for _ in range(3)]
        specs += [
            {"effects": [], "ool": k, "enr": 1.0}
            for k in ("bouc-wen-hysteresis", "opposite-sign-mode", "sensor-1/f-noise")
        ]
        specs += [
            {
                "effects": ["structural-mode", "tool-radius-error"],
                "ool": None,
                "enr": 0.3,
            },
            {
                "effects": ["loop-delay", "base-vibration-lines"],
                "ool": None,
                "enr": 0.3,
            },
        ]
    else:
        for e in C.EFFECTS:
            for enr in ENRS:
                for _ in range(5):
                    specs.append({"effects": [e], "ool": None, "enr": enr})
        specs += [{"effects": [], "ool": None, "enr": 0.0} for _ in range(20)]
        for i, k in enumerate(C.OOL * 2):
            specs.append({"effects": [], "ool": k, "enr": 0.3 if i < 5 else 1.0})
        rng = np.random.default_rng(seed + 1)
        for i in range(10):
            a, b = rng.choice(len(C.EFFECTS), 2, replace=False)
            specs.append(
                {
                    "effects": [C.EFFECTS[a], C.EFFECTS[b]],
                    "ool": None,
                    "enr": 0.1 if i % 2 else 0.3,
                }
            )
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(specs))
    out = []
    for n, i in enumerate(order):
        s = dict(specs[i])
        s["seed"] = int(seed * 100003 + 31 * n + 7)
        s["case"] = f"case_{n:04d}"
        out.append(s)
    return out


def _keystream(secret: bytes, n: int) -> bytes:
    out = bytearray()
    k = 0
    while len(out) < n:
        out += hashlib.sha256(secret + k.to_bytes(8, "little")).digest()
        k += 1
    return bytes(out[:n])


def seal(key: dict, out: Path) -> None:
    """Write the sealed key, its secret and the commitment hash."""
    plain = json.dumps(key, sort_keys=True).encode()
    secret = secrets.token_bytes(32)
    comp = zlib.compress(plain, 9)
    enc = bytes(a ^ b for a, b in zip(comp, _keystream(secret, len(comp)), strict=True))
    (out / "key.sealed").write_bytes(base64.b64encode(enc))
    (out / "key.secret").write_text(secret.hex())
    (out / "key.sha256").write_text(hashlib.sha256(plain).hexdigest())


def unseal(out: Path) -> dict:
    """Open the sealed key (checks the commitment hash)."""
    enc = base64.b64decode((out / "key.sealed").read_bytes())
    secret = bytes.fromhex((out / "key.secret").read_text().strip())
    comp = bytes(a ^ b for a, b in zip(enc, _keystream(secret, len(enc)), strict=True))
    plain = zlib.decompress(comp)
    if hashlib.sha256(plain).hexdigest() != (out / "key.sha256").read_text().strip():
        raise RuntimeError("the key does not match its commitment hash")
    return json.loads(plain)


def make_one(args) -> dict:
    """Generate one case folder; returns its key entry."""
    spec, campaign_name, root = args
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import cases as C

    campaign = C.CAMPAIGNS[campaign_name]
    try:
        p, ool, truth, achieved = C.build(spec, campaign)
    except RuntimeError as exc:  # target ENR unreachable: no case, said in the key
        return {
            "case": spec["case"],
            "effects": spec["effects"],
            "ool": spec["ool"],
            "enr": spec["enr"],
            "seed": spec["seed"],
            "generation_error": str(exc),
            "campaign": campaign_name,
        }
    C.write_case(Path(root) / "cases" / spec["case"], p, ool, campaign, spec["seed"])
    return {
        "case": spec["case"],
        "effects": spec["effects"],
        "ool": spec["ool"],
        "enr": spec["enr"],
        "enr_achieved": achieved,
        "noise_scale": spec.get("noise_scale"),
        "low_band": spec.get("low_band"),
        "null": spec.get("null"),
        "seed": spec["seed"],
        "truth": truth,
        "campaign": campaign_name,
    }


def generate(
    out: Path, *, quick: bool, seed: int = 1, jobs: int = 2, limit: int | None = None
) -> list[dict]:
    """Generate the suite into ``out`` and seal the key."""
    import multiprocessing as mp

    out = Path(out)
    (out / "cases").mkdir(parents=True, exist_ok=True)
    specs = suite(quick, seed)
    if limit:
        specs = specs[:limit]
    camp = "quick" if quick else "full"
    work = [(s, camp, str(out)) for s in specs]
    if jobs > 1:
        ctx = mp.get_context("spawn")
        with ctx.Pool(jobs) as pool:
            key = list(pool.imap(make_one, work))
    else:
        key = [make_one(w) for w in work]
    seal({"cases": key, "seed": seed, "quick": quick}, out)
    return key


def generate_specs(
    out: Path,
    specs: list[dict],
    *,
    campaign: str = "test",
    seed: int = 1,
    jobs: int = 1,
) -> list[dict]:
    """Generate given case specs (``effects``, ``ool``, ``enr``) and seal the key.

    Used by the tests for a small blind subset on a short campaign.
    """
    import multiprocessing as mp

    out = Path(out)
    (out / "cases").mkdir(parents=True, exist_ok=True)
    full = []
    for n, sp in enumerate(specs):
        s = {
            "effects": list(sp.get("effects", [])),
            "ool": sp.get("ool"),
            "enr": float(sp.get("enr", 0.0)),
            "seed": int(seed * 1009 + 17 * n),
            "case": f"case_{n:04d}",
        }
        if sp.get("noise_scale"):
            s["noise_scale"] = [float(c) for c in sp["noise_scale"]]
        if sp.get("low_band"):
            s["low_band"] = float(sp["low_band"])
        if sp.get("null"):
            s["null"] = sp["null"]
        full.append(s)
    work = [(s, campaign, str(out)) for s in full]
    if jobs > 1:
        with mp.get_context("spawn").Pool(jobs) as pool:
            key = list(pool.imap(make_one, work))
    else:
        key = [make_one(w) for w in work]
    seal({"cases": key, "seed": seed, "quick": True}, out)
    return key


#: Realistic null kinds (issue 19 items 5 and 9): no effect, only what a real
#: machine's records hold besides the machine file's noise.
REALISTIC_NULLS = {
    "nominal": {},
    "low-band base (f^-4 below fs/4096)": {"low_band": 4.0},
    "noise factor (base x2, sensor x1.5)": {"noise_scale": (2.0, 1.5, 1.0)},
}


def realistic_null_specs(k: int) -> list[dict]:
    """``k`` null specs of each kind of :data:`REALISTIC_NULLS` (kinds interleaved)."""
    return [
        {"effects": [], "ool": None, "enr": 0.0, "null": name, **extra}
        for _ in range(k)
        for name, extra in REALISTIC_NULLS.items()
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="output folder")
    ap.add_argument("--quick", action="store_true", help="small subset, short campaign")
    ap.add_argument("--seed", type=int, default=1, help="suite seed")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--limit", type=int, help="only the first N cases")
    ap.add_argument("--realistic-nulls", type=int, metavar="K",
                    help="instead of the suite: K null cases of each realistic kind "
                    "(nominal, low-band base, noise factor) on the test campaign")
    a = ap.parse_args(argv)
    if a.realistic_nulls:
        key = generate_specs(Path(a.out), realistic_null_specs(a.realistic_nulls),
                             campaign="test", seed=a.seed, jobs=a.jobs)
        print(f"{len(key)} null cases in {a.out}/cases; key sealed in "
              f"{a.out}/key.sealed")
        return 0
    key = generate(Path(a.out), quick=a.quick, seed=a.seed, jobs=a.jobs, limit=a.limit)
    print(f"{len(key)} cases in {a.out}/cases; key sealed in {a.out}/key.sealed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
