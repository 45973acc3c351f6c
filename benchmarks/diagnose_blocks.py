"""Time the diagnosis's map-block noise model: block build and its linear algebra.

Usage::

    python benchmarks/diagnose_blocks.py [--out DIR]

Generates one null case of the project's discovery suite on its short ``test``
campaign (a 200 x 260 map and one ring profile of the 5 um lenslet cut, plus the
time records), builds the diagnosis's blocks at the nominal model, and times the
map blocks' noise weighting (``PointsBlock._build_weights``) against the dense
algebra it replaced, on the largest segment covariance of the case (the ring
profile's interval statistics):

* the tool-noise likelihood terms: Householder tridiagonalisation and banded
  solves (``_tridiagonal``) against ``numpy.linalg.eigh``;
* the inverse Cholesky factor: LAPACK ``dtrtri`` against ``solve_triangular`` with
  the identity;
* the sparse whitening operator: direct CSR assembly against
  ``scipy.sparse.block_diag``.

Prints the seconds and the ratios (BLAS limited to one thread, as in a
diagnosis). Correctness is tested in ``tests/diagnose/test_blocks.py``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _best(fn, repeat: int = 3) -> float:
    t = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return min(t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for the generated case (default: a temporary one)")
    a = ap.parse_args(argv)
    import numpy as np
    import scipy as sp
    import scipy.sparse  # noqa: F401

    from servosurf._defaults import blas_threads
    from servosurf.diagnose import Model, build_case, load_manifest
    from servosurf.diagnose._blocks import (
        Context,
        PointsBlock,
        _lower_block_diag,
        _lower_inverse,
        _tridiagonal,
        _tridiagonal_quad,
    )
    from servosurf.diagnose._diagnose import _make_blocks

    sys.path.insert(0, str(HERE / "discovery"))
    import generate

    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or Path(tmp)
        generate.generate_specs(out, [{"effects": [], "enr": 0.0}], campaign="test",
                                seed=5, jobs=1)
        man = load_manifest(next((out / "cases").glob("case_*")) / "manifest.toml")
        with blas_threads(1):
            ctx = Context(build_case(man))
            t0 = time.perf_counter()
            blocks = _make_blocks(man, ctx, Model())
            t_all = time.perf_counter() - t0
            pts = [b for b in blocks if isinstance(b, PointsBlock)]
            print(f"blocks of the case: {t_all:.2f} s ({len(blocks)} blocks, "
                  f"{len(pts)} map/profile)")
            seg, ch = max((s for b in pts for s in b.segments), key=lambda s: s[0].size)
            c = ch @ ch.T
            n = c.shape[0]
            rng = np.random.default_rng(0)
            b = rng.standard_normal(n)

            def dense_ml():
                lam, v = np.linalg.eigh(c)
                proj = (v.T @ b) ** 2
                return [float(np.sum(np.log(k * lam + 1.0) + proj / (k * lam + 1.0)))
                        for k in (0.5, 1.0, 2.0)]

            def tri_ml():
                d, e, z = _tridiagonal(c, b)
                lam = sp.linalg.eigh_tridiagonal(d, e, eigvals_only=True)
                return [float(np.sum(np.log(k * lam + 1.0))
                              + _tridiagonal_quad(d, e, z, k, 1.0))
                        for k in (0.5, 1.0, 2.0)]

            rows = [
                ("likelihood terms (eigh -> tridiagonal)", dense_ml, tri_ml),
                ("inverse factor (solve_triangular -> dtrtri)",
                 lambda: sp.linalg.solve_triangular(ch, np.eye(n), lower=True),
                 lambda: _lower_inverse(ch)),
            ]
            inv = _lower_inverse(ch)
            rows.append(("whitening operator (block_diag -> CSR)",
                         lambda: sp.sparse.block_diag([inv], format="csr"),
                         lambda: _lower_block_diag([inv])))
            print(f"largest segment: {n} interval statistics")
            for name, old, new in rows:
                t_old, t_new = _best(old), _best(new)
                print(f"  {name}: {t_old:.3f} s -> {t_new:.3f} s "
                      f"(x{t_old / max(t_new, 1e-9):.1f})")
            print(f"  likelihood terms agree to "
                  f"{max(abs(x - y) / abs(x) for x, y in zip(dense_ml(), tri_ml())):.1e}"
                  " (relative)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
