"""The README, followed literally after installing the wheel (issue 20).

The wheel is built from a copy of the repository with this environment's setuptools
(no build isolation, no download) and installed without dependencies into a fresh
virtual environment, which sees this environment's site-packages through a ``.pth``
file placed after its own (so its ``servosurf`` is the wheel's, never the source
tree's). Every command of the README's ``sh`` blocks then runs from an empty folder
with that environment's ``servosurf`` first on PATH: the tour is the test's input,
so a command the README documents cannot stop working unnoticed.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def readme_commands(text: str) -> list[tuple[str, int]]:
    """``(command, expected exit status)`` of every command in the README's ``sh``
    blocks: lines starting with ``servosurf`` or ``python -c``; a trailing
    ``# exit N`` comment sets the expected status (default 0)."""
    out: list[tuple[str, int]] = []
    for block in re.findall(r"^```sh\n(.*?)^```", text, flags=re.M | re.S):
        for line in block.splitlines():
            line = line.strip()
            if not (line.startswith("servosurf") or line.startswith("python -c")):
                continue
            status = 0
            m = re.search(r"\s+#\s*exit (\d+)\s*$", line)
            if m:
                status = int(m.group(1))
                line = line[: m.start()]
            if (line, status) not in out:  # a command shown twice runs once
                out.append((line, status))
    return out


def test_readme_commands_are_found():
    cmds = readme_commands((REPO / "README.md").read_text())
    assert cmds[0] == ("servosurf simulate lenslet_5um", 0)  # the main job first
    names = {shlex.split(c)[1] for c, _ in cmds if c.startswith("servosurf")}
    for command in ("toolpaths", "simulate", "face", "noise", "paper", "compare",
                    "identify", "psd", "info", "convert", "machines"):
        assert command in names, f"README documents no `servosurf {command}`"
    assert any(s == 1 for _, s in cmds)  # the one-line error example


def _site_dirs() -> list[str]:
    dirs = [p for p in sys.path if p.rstrip(os.sep).endswith(("site-packages",
                                                              "dist-packages"))]
    return list(dict.fromkeys(dirs))


@pytest.mark.slow
def test_wheel_install_runs_every_readme_command(tmp_path):
    t0 = time.perf_counter()
    src = tmp_path / "src"
    shutil.copytree(REPO, src, symlinks=True, ignore=shutil.ignore_patterns(
        ".git", "__pycache__", "build", "dist", "*.egg-info", ".pytest_cache",
        "results", ".hypothesis", ".benchmarks"))
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                    "--no-build-isolation", "--no-index", "-q", "-w", str(dist),
                    str(src)], check=True, capture_output=True, text=True)
    wheel = next(dist.glob("servosurf-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)],
                   check=True)
    py = venv / "bin" / "python"
    purelib = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True).stdout.strip()
    # the wheel first: with this environment visible, pip would find its own
    # (non-editable) servosurf of the same version "already satisfied" and skip
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install",
                    "--no-deps", "--no-index", "-q", str(wheel)], check=True,
                   capture_output=True, text=True)
    # the dependencies come from this environment, after the venv's own packages
    (Path(purelib) / "zz_test_environment.pth").write_text(
        "\n".join(_site_dirs()) + "\n")
    bindir = Path(sysconfig.get_path("scripts", vars={"base": str(venv)}))
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "SERVOSURF_QUIET")}
    env["PATH"] = os.pathsep.join([str(bindir), env.get("PATH", "")])
    work = tmp_path / "empty"
    work.mkdir()
    where = subprocess.run(
        ["python", "-c", "import servosurf, servosurf.toolpath as t; "
         "print(servosurf.__file__); print(t.builtin_toolpaths()['lenslet_5um'])"],
        cwd=work, env=env, check=True, capture_output=True, text=True)
    module, builtin = where.stdout.split()
    assert Path(module).is_relative_to(venv)  # the wheel's copy, not the source
    assert Path(builtin).is_relative_to(venv) and not Path(builtin).is_symlink()
    assert shutil.which("servosurf", path=env["PATH"]) == str(bindir / "servosurf")

    if (REPO / "examples").is_dir():  # commands that read the shipped examples
        shutil.copytree(REPO / "examples", work / "examples")
    commands = readme_commands((REPO / "README.md").read_text())
    # jobs: a `python -c` line that writes an input runs with the command after it
    jobs: list[list[tuple[str, int]]] = []
    pending: list[tuple[str, int]] = []
    for item in commands:
        pending.append(item)
        if not item[0].startswith("python -c"):
            jobs.append(pending)
            pending = []
    if pending:
        jobs.append(pending)
    assert jobs[0] == [("servosurf simulate lenslet_5um", 0)]
    log: list[str] = []

    def run(job):
        for command, status in job:
            t1 = time.perf_counter()
            res = subprocess.run(command, shell=True, cwd=work, env=env,
                                 capture_output=True, text=True, timeout=900)
            log.append(f"{time.perf_counter() - t1:6.1f} s  {command}")
            assert res.returncode == status, (command, res.stdout[-2000:],
                                              res.stderr[-2000:])
            assert "Traceback" not in res.stderr, (command, res.stderr[-2000:])
            if status:
                assert len(res.stderr.strip().splitlines()) == 1, (command,
                                                                   res.stderr)
            kernel = command.startswith(("servosurf simulate", "servosurf face"))
            notice = "first run: compiling the surface kernel" in res.stderr
            # the first run compiles the kernel and says so; no later run does
            assert notice == (kernel and not status and job is jobs[0]), (
                command, res.stderr[-2000:])
            if job is jobs[0]:
                assert "max form error" in res.stdout and "wrote " in res.stdout
            if command == "servosurf paper":
                assert "skipped" not in res.stdout + res.stderr  # surface rows ran
                assert "5 um lenslet: maximum form error" in res.stdout
                # the reduced calibration re-run (calibrate(reduced_from=machine)):
                # every calibrated number within COMPARE_RTOL of the shipped one.
                # This is the suite's only run of it (150 s).
                from servosurf.calibration import COMPARE_RTOL

                m = re.search(r"calibration re-run: (\d+) constants, largest relative "
                              r"difference (\S+) \((within|OUTSIDE) (\S+)\)", res.stdout)
                assert m, res.stdout[-2000:]
                assert int(m.group(1)) >= 12 and m.group(3) == "within", m.group(0)
                assert float(m.group(4)) == COMPARE_RTOL
                assert float(m.group(2)) <= COMPARE_RTOL

    run(jobs[0])  # compiles and caches the kernel; then two at a time (2 cores)
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=2) as pool:
        for fut in [pool.submit(run, job) for job in jobs[1:]]:
            fut.result()
    assert (work / "results" / "lenslet_5um" / "summary.json").is_file()
    print("\n".join(log), f"\ntotal {time.perf_counter() - t0:.1f} s")
