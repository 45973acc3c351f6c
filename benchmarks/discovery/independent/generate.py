"""Generate independent discovery cases: manifests, recordings and a sealed key.

Usage::

    python benchmarks/discovery/independent/generate.py --seed N --out DIR \\
        --n-cases K [--jobs 1]

Writes ``DIR/cases/case_NNNN/`` (``manifest.toml`` and recordings only; case
numbers are a seeded shuffle) and the key outside the case folders:
``DIR/key.sealed`` (zlib-compressed JSON XOR-ed with a SHA-256 counter keystream
of a random secret), ``DIR/key.secret`` and ``DIR/key.sha256`` (SHA-256 of the
plain key, written before any diagnosis runs).

The suite (36 cases for ``--n-cases 36``; other counts take a seeded stratified
share): every catalogue-like effect of :mod:`effects` at ENR 0.1 and 0.3, every
out-of-catalogue effect once (ENR 0.3 or 1), and six nulls (nominal noise, base
vibration below fs / 4096, a noise PSD off by 1.5-2x), each with its own drawn
campaign.

ENR (effect-to-noise ratio), the key's ``enr_definition``: for every recording
the RMS of the change the effect makes (same noise realisation, or noise-free for
deterministic effects) over the RMS of that recording's noise (the machine
file's PSDs through the loop over [fs/4096, logger Nyquist]; FRFs: RMS of
|log(h1/h0)| over the relative FRF noise; maps and profiles: over the points
cut in both, against tool and instrument noise), maximised over recordings.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import math
import secrets
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

from independent import campaign as CP  # noqa: E402
from independent import effects as E  # noqa: E402
from independent.loop import simulate  # noqa: E402

ENRS = (0.1, 0.3)
OOC_ENRS = (0.3, 1.0)
#: Largest accepted ratio between the achieved and the target ENR.
ENR_TOLERANCE = 1.15
#: Effect draws tried before a case is given up.
MAX_DRAWS = 6

ENR_DEFINITION = __doc__.split("ENR (effect-to-noise ratio), the key's")[1].split(
    '"""')[0].strip()


def suite(n_cases: int, seed: int, enrs: tuple = ENRS) -> list[dict]:
    """Case specifications: ``{"effect", "enr"}`` in a seeded order.

    ``enrs`` are the target ENRs of every catalogue-like effect (one case each).
    """
    full = []
    for name in E.CATALOGUE_LIKE:
        for enr in enrs:
            full.append({"effect": name, "enr": enr})
    for i, name in enumerate(E.OUT_OF_CATALOGUE):
        full.append({"effect": name, "enr": OOC_ENRS[i % 2]})
    for name in E.NULLS:
        full += [{"effect": name, "enr": 0.0}] * 2
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(full))
    if n_cases <= len(full):
        # stratified share: every block keeps its proportion
        blocks: dict = {}
        for i in order:
            k = _block(full[i]["effect"])
            blocks.setdefault(k, []).append(full[i])
        out = []
        while len(out) < n_cases:
            for k in sorted(blocks):
                if blocks[k] and len(out) < n_cases:
                    out.append(blocks[k].pop(0))
        return out
    return [full[order[i % len(full)]] for i in range(n_cases)]


def _block(name: str) -> str:
    if name in E.CATALOGUE_LIKE:
        return "a"
    if name in E.OUT_OF_CATALOGUE:
        return "b"
    return "c"


def stable(ctx, spec) -> bool:
    """The loop with the spec's effects settles after a 1 nm step."""
    fs = ctx.mach.fs
    n = int(0.2 * fs)
    o = simulate(ctx.mach, ctx.ctrl, np.full(n, 1e-9), eff=spec.loop)
    fe = o["fe"]
    if not np.all(np.isfinite(fe)):
        return False
    late = np.max(np.abs(fe[-int(0.03 * fs):]))
    mid = np.max(np.abs(fe[int(0.05 * fs):int(0.08 * fs)]))
    return bool(late <= 0.5 * mid or late < 1e-15)


def _groups(eff) -> set | None:
    if eff.needs_noise:
        return {"idle", "air", "air_b", "cut"}
    return None


def measure_enr(ctx, camp, eff, s, seed, rec0, sigma) -> dict:
    """ENR per recording of ``eff`` at strength ``s`` (inf when unstable)."""
    spec = eff.make(s)
    if spec.loop.linear.mode_mass > 0 and not stable(ctx, spec):
        return {"unstable": math.inf}
    rec = CP.recordings(ctx, camp, spec, seed, clean=not eff.needs_noise,
                        only=_groups(eff))
    return CP.enr_by_recording(rec, rec0, sigma)


def scale_to_enr(ctx, camp, eff, target, seed, rec0, sigma, *, max_eval: int = 16):
    """Strength with ENR = target: bracket, then log-log regula falsi.

    Returns ``(s, enr, enr_by_recording)`` of the closest evaluation.
    """

    def f(s):
        if s > eff.s_max:  # physically implausible: treated like an unstable loop
            return math.inf, {"implausible": math.inf}
        e = measure_enr(ctx, camp, eff, s, seed, rec0, sigma)
        return (max(e.values()) if e else 0.0), e

    def err(e):
        return abs(math.log(e / target)) if np.isfinite(e) and e > 0 else math.inf

    s = eff.s0
    e, per = f(s)
    best = (err(e), s, e, per)
    lo = hi = None  # (s, e) below / above the target
    for _ in range(max_eval - 1):
        if err(e) < 0.03:
            break
        if not np.isfinite(e) or e > target:
            hi = (s, e)
        else:
            lo = (s, e)
        if lo and hi:
            fin = np.isfinite(hi[1]) and lo[1] > 0
            if fin:
                sl = math.log(hi[1] / lo[1]) / math.log(hi[0] / lo[0])
                s_new = lo[0] * (target / lo[1]) ** (1.0 / sl)
            else:
                s_new = math.sqrt(lo[0] * hi[0])
            a, b = math.log(lo[0]), math.log(hi[0])
            x = math.log(s_new)
            if not (min(a, b) + 0.05 * abs(b - a) < x < max(a, b) - 0.05 * abs(b - a)):
                s_new = math.exp(0.5 * (a + b))
        elif hi:
            r = target / hi[1] if np.isfinite(hi[1]) else 0.1
            s_new = hi[0] * min(max(r, 1e-3), 1 / 1.5)
        else:
            r = target / lo[1] if lo[1] > 0 else 10.0
            s_new = lo[0] * min(max(r, 1.5), 1e3)
        s = s_new
        e, per = f(s)
        if err(e) < best[0]:
            best = (err(e), s, e, per)
    return best[1], best[2], best[3]


def null_enr(ctx, camp, spec) -> dict:
    """ENR of a noise-model change: sqrt(|sigma1^2 - sigma0^2|) / sigma0."""
    s0 = CP.noise_rms(ctx, camp)
    s1 = CP.noise_rms(ctx, camp, spec)
    return {k: math.sqrt(abs(s1[k] ** 2 - s0[k] ** 2)) / s0[k] for k in s0
            if s0[k] > 0 and k in s1}


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


def draw(rng, name: str, ctx):
    """One draw of case ``name``: ``(effect, campaign, noise seed)`` from ``rng``
    (the case's generator; :mod:`oracle` replays the same sequence)."""
    eff = E.ALL[name](rng, ctx)
    camp = CP.draw_campaign(rng, eff.channels, ctx)
    if name == "null-lowfreq":
        camp.low_freq_base = True
    elif name == "null-nominal":
        camp.low_freq_base = False
    return eff, camp, int(rng.integers(2**31))


def make_case(index: int, spec: dict, seed: int, folder: Path, *,
              chip_hold: bool = False) -> dict:
    """Draw, scale and write one case; returns its key entry."""
    t_start = time.perf_counter()
    ctx = CP.context(chip_hold)
    rng = np.random.default_rng([seed, index])
    name = spec["effect"]
    entry = {"effect": name, "enr_target": spec["enr"]}
    for _draw in range(MAX_DRAWS):
        eff, camp, nseed = draw(rng, name, ctx)
        if eff.klass == "null":
            s, e, per = 0.0, 0.0, {}
            sp = eff.make(0.0)
            per = null_enr(ctx, camp, sp)
            e = max(per.values()) if per else 0.0
            break
        sigma = CP.noise_rms(ctx, camp)
        rec0 = CP.recordings(ctx, camp, CP.nominal_spec(), nseed,
                             clean=not eff.needs_noise, only=_groups(eff))
        s, e, per = scale_to_enr(ctx, camp, eff, spec["enr"], nseed, rec0, sigma)
        if np.isfinite(e) and e > 0 and abs(math.log(e / spec["enr"])) <= math.log(
                ENR_TOLERANCE):
            sp = eff.make(s)
            break
    else:
        entry["generation_error"] = (
            f"ENR {spec['enr']} not reached in {MAX_DRAWS} draws (last {e:.3g})")
        return entry
    rec = CP.recordings(ctx, camp, sp, nseed)
    CP.write_case(folder, ctx, camp, rec)
    entry.update(
        klass=eff.klass,
        expected=list(eff.expected),
        form=eff.form,
        strength=s,
        enr=e,
        enr_by_recording=per,
        truth=_jsonable(sp.truth),
        comparable=_jsonable(sp.comparable),
        noise_scale=sp.noise_scale,
        campaign=_jsonable(camp.summary()),
        noise_seed=nseed,
        generation_s=time.perf_counter() - t_start,
    )
    return entry


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=HERE, text=True,
                              capture_output=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _keystream(secret: bytes, n: int) -> bytes:
    out = bytearray()
    i = 0
    while len(out) < n:
        out += hashlib.sha256(secret + i.to_bytes(8, "big")).digest()
        i += 1
    return bytes(out[:n])


def seal(out: Path, key: dict) -> None:
    """Write the sealed key, its secret and the SHA-256 commitment."""
    plain = json.dumps(key, sort_keys=True).encode()
    secret = secrets.token_bytes(32)
    data = zlib.compress(plain, 9)
    ks = _keystream(secret, len(data))
    sealed = bytes(a ^ b for a, b in zip(data, ks, strict=True))
    (out / "key.sealed").write_bytes(base64.b64encode(sealed))
    (out / "key.secret").write_text(secret.hex())
    (out / "key.sha256").write_text(hashlib.sha256(plain).hexdigest())


def unseal(out: Path) -> dict:
    """Open the key (checks the commitment)."""
    out = Path(out)
    sealed = base64.b64decode((out / "key.sealed").read_bytes())
    secret = bytes.fromhex((out / "key.secret").read_text().strip())
    ks = _keystream(secret, len(sealed))
    plain = zlib.decompress(bytes(a ^ b for a, b in zip(sealed, ks, strict=True)))
    if hashlib.sha256(plain).hexdigest() != (out / "key.sha256").read_text().strip():
        raise RuntimeError(f"{out}: key does not match its SHA-256 commitment")
    return json.loads(plain)


def _work(args):
    i, spec, seed, folder, hold = args
    try:
        return make_case(i, spec, seed, Path(folder), chip_hold=hold)
    except Exception as exc:  # a failed case is recorded, not fatal
        return {"effect": spec["effect"], "enr_target": spec["enr"],
                "generation_error": f"{type(exc).__name__}: {exc}"}


def null_suite(k: int) -> list[dict]:
    """``k`` cases of each null kind (:data:`effects.NULLS`: nominal noise, base
    vibration below fs / 4096, a noise PSD off by 1.5-2x), kinds interleaved."""
    return [{"effect": name, "enr": 0.0} for _ in range(k) for name in E.NULLS]


def generate(out: Path, *, seed: int, n_cases: int, jobs: int = 1,
             chip_force: str = "continuous", enrs: tuple = ENRS,
             progress=print, nulls: int = 0) -> dict:
    """Generate the suite into ``out`` and seal its key; returns the (plain) key.

    With ``nulls`` > 0, only ``nulls`` cases of each null kind (:func:`null_suite`).
    """
    out = Path(out)
    (out / "cases").mkdir(parents=True, exist_ok=True)
    specs = null_suite(nulls) if nulls > 0 else suite(n_cases, seed, enrs)
    rng = np.random.default_rng(seed + 17)
    numbers = rng.permutation(len(specs)) + 1
    hold = chip_force == "held"
    tasks = [(i, sp, seed, str(out / "cases" / f"case_{numbers[i]:04d}"), hold)
             for i, sp in enumerate(specs)]
    entries = [None] * len(tasks)
    if jobs > 1:
        import multiprocessing as mp

        with mp.get_context("spawn").Pool(jobs) as pool:
            for k, res in enumerate(pool.imap(_work, tasks)):
                entries[k] = res
                progress(f"case {k + 1}/{len(tasks)} done")
    else:
        for k, t in enumerate(tasks):
            entries[k] = _work(t)
            e = entries[k]
            progress(f"case {k + 1}/{len(tasks)}: {e['effect']} "
                     f"ENR {e.get('enr', float('nan')):.3g} "
                     f"({e.get('generation_s', 0):.1f} s)"
                     + (f" ERROR {e['generation_error']}"
                        if "generation_error" in e else ""))
    for k, e in enumerate(entries):
        e["case"] = f"case_{numbers[k]:04d}"
    key = {"generator": "benchmarks/discovery/independent", "commit": _commit(),
           "seed": seed, "chip_force": chip_force, "enr_definition": ENR_DEFINITION,
           "cases": entries}
    seal(out, _jsonable(key))
    return key


def _enr_list(text: str) -> tuple:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--enrs {text!r}: expected comma-separated numbers") from None
    if not vals or any(not (0.0 < v < 100.0) for v in vals):
        raise argparse.ArgumentTypeError(
            f"--enrs {text!r}: every ENR must be in (0, 100)")
    return vals


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="suite seed")
    ap.add_argument("--out", type=Path, required=True, help="output directory")
    ap.add_argument("--n-cases", type=int, default=36, help="number of cases")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--chip-force", choices=("continuous", "held"),
                    default="continuous",
                    help="chip force following the tool inside the integrator "
                    "(physics, default) or held over each controller sample "
                    "(servosurf's loop model)")
    ap.add_argument("--enrs", type=_enr_list, default=ENRS,
                    help="target ENRs of the catalogue-like effects, comma "
                    "separated (default 0.1,0.3; '0.3' gives a 24-case suite)")
    ap.add_argument("--nulls", type=int, default=0, metavar="K",
                    help="instead of the suite: K cases of each null kind "
                    "(nominal, low-frequency base, misspecified noise)")
    a = ap.parse_args(argv)
    if a.nulls < 0:
        print(f"error: --nulls {a.nulls}: must be 0 or more", file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    key = generate(a.out, seed=a.seed, n_cases=a.n_cases, jobs=a.jobs,
                   chip_force=a.chip_force, enrs=a.enrs, nulls=a.nulls)
    bad = sum(1 for c in key["cases"] if "generation_error" in c)
    print(f"{len(key['cases'])} cases ({bad} not generated) in "
          f"{time.perf_counter() - t0:.0f} s -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
