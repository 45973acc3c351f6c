"""Figures a precision engineer would publish (issue 20): robust colour scales, every
peak labelled without overlaps, axes named for what they show, 3-D rulers apart."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.metrology import Surface
from servosurf.viz import _render
from servosurf.viz import _surface_plots as sp


@pytest.fixture()
def captured(monkeypatch):
    """Figures handed to the PNG writer, kept for inspection."""
    figs = []

    def keep(fig, path, dpi):
        figs.append(fig)
        return path

    monkeypatch.setattr(sp, "_save_atomic", keep)
    return figs


def test_robust_colour_scale_ignores_a_rim(captured, tmp_path):
    rng = np.random.default_rng(7)  # texture uniform in [-1, 1] nm
    z = rng.uniform(-1e-9, 1e-9, (100, 100))
    z[0, :30] = -14e-9  # a rim artefact: 0.3 % of the pixels, 14x the texture
    surf = Surface(z, 1e-6, 1e-6)
    sp.plot_map(surf, tmp_path / "a.png")
    sp.plot_map(surf, tmp_path / "b.png", robust=0.5)
    full = captured[0].axes[0].images[0].get_clim()
    robust = captured[1].axes[0].images[0].get_clim()
    assert full[0] == pytest.approx(-14.0)  # nm: the rim sets the full scale
    # the 0.5 / 99.5 percentiles: the rim's 0.3 % lies below the 0.5 % point, so
    # the low end stays near -1 nm (0.2 % into the uniform texture), not -14
    assert -1.0 < robust[0] < -0.95 and 0.95 < robust[1] < 1.0
    label = captured[1].axes[1].get_ylabel()
    assert "0.5-99.5 percentile" in label
    with pytest.raises(ValueError, match="robust"):
        sp.plot_map(surf, tmp_path / "c.png", robust=60)


def test_every_spectrum_peak_labelled_without_overlap(captured, tmp_path):
    f = np.linspace(0, 900e3, 451)  # 1/m
    p = np.full_like(f, 1e-23)
    peaks = []
    for fm, amp in ((56e3, 1e-20), (128e3, 3e-22), (150e3, 2e-22), (174e3, 3e-21),
                    (277e3, 1.5e-22)):
        k = int(np.argmin(abs(f - fm)))
        p[k] = amp
        peaks.append({"freq_per_m": f[k], "psd_m3": amp})
    sp.plot_spectrum(f, p, peaks, tmp_path / "s.png", speed=0.0423, fmin=80e3)
    fig = captured[0]
    ax = fig.axes[0]
    labels = [t for t in ax.texts if "mm" in t.get_text() and "kHz" in t.get_text()]
    assert len(labels) == len(peaks)  # every peak, including the one below fmin
    shown = sorted(float(t.get_text().split()[0]) for t in labels)
    assert shown == pytest.approx([56, 128, 150, 174, 277], abs=1)
    # kHz = (1/m) x (m/s): 174 mm^-1 at 42.3 mm/s is 7.36 kHz
    assert any("7.36 kHz" in t.get_text() for t in labels)
    from matplotlib.text import Text

    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [Text.get_window_extent(t, r) for t in labels]  # the text alone
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert not boxes[i].overlaps(boxes[j]), (labels[i].get_text(),
                                                    labels[j].get_text())
    # the line from each label down to its peak crosses no other label
    for i, t in enumerate(labels):
        peak = ax.transData.transform(t.xy)
        foot = np.array([0.5 * (boxes[i].x0 + boxes[i].x1), boxes[i].y0])
        for s in np.linspace(0, 1, 200):
            x, y = foot + s * (peak - foot)
            for j, b in enumerate(boxes):
                if j != i:
                    assert not (b.x0 < x < b.x1 and b.y0 < y < b.y1), (
                        t.get_text(), labels[j].get_text())
    axes_box = ax.get_window_extent(r)
    for b in boxes:  # labels stay inside the plot (not over the title)
        assert b.y1 <= axes_box.y1 + 1 and b.y0 >= axes_box.y0 - 1
    below = [t for t in labels if t.get_text().startswith("56")][0]
    assert below.get_color() != "black"  # drawn apart: below the high-pass


def test_profile_axis_and_legend_name_what_is_plotted(captured, tmp_path):
    y = np.linspace(-70e-6, 70e-6, 50)
    z = -5e-6 + (y / 70e-6) ** 2 * 5e-6
    sp.plot_profile_with_form_error(y, z, z, 0 * z, tmp_path / "p.png",
                                    xlabel="y, along the cut (um)",
                                    label="simulated")
    fig = captured[0]
    assert fig.axes[1].get_xlabel() == "y, along the cut (um)"
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == [
        "simulated", "nominal"]


def test_render_rulers_do_not_share_corners(monkeypatch):
    """Three separate rulers: no two of their ends meet (the old box axes put the
    end labels of all three axes on shared corners)."""
    x = np.linspace(-60e-6, 60e-6, 40)
    zz = -2e-6 * np.exp(-(x[None, :] ** 2 + x[:, None] ** 2) / (30e-6) ** 2)
    lens = Surface(zz, x[1] - x[0], x[1] - x[0], x0=10e-3 + x[0], y0=x[0])
    scene = _render._scene(lens, 1, None)
    # 10 mm off the axis: lateral axes about the centre, short tick labels
    assert scene["xtitle"] == "x - 10 mm (um)"
    assert np.ptp(scene["points"][:, 0]) == pytest.approx(120.0, rel=1e-9)
    assert abs(scene["points"][:, 0].mean()) < 1.0  # um, about the centre

    class Recorder:
        def __init__(self):
            self.rulers = []

        def add_ruler(self, a, b, **kw):
            self.rulers.append((np.array(a, float), np.array(b, float), kw))

    pl = Recorder()
    _render._add_rulers(pl, scene)
    assert len(pl.rulers) == 3
    ends = [(i, e) for i, (a, b, _) in enumerate(pl.rulers) for e in (a, b)]
    gap = 0.1 * 120.0
    for i, e in ends:
        for j, g in ends:
            if i < j:
                assert np.linalg.norm(e[:2] - g[:2]) >= gap * 0.99
    z_ruler = pl.rulers[2][2]
    # the z ruler reads true heights: drawn um divided by the exaggeration
    assert z_ruler["scale"] == pytest.approx(1.0 / scene["exaggeration"])


def test_face_preview_is_an_area_mean():
    """Block means against a plain loop, NaN blocks and statistics by hand."""
    from servosurf.scale import face_preview

    rng = np.random.default_rng(11)
    z = rng.normal(-5e-6, 1e-9, (53, 47))
    z[:10, :12] = np.nan  # off the face
    z[20, 30] = np.nan
    prev, step, stats = face_preview(z, max_pixels=10, window=16)
    assert step == 6  # ceil(53 / 10)
    assert prev.shape == (9, 8)
    for i in range(prev.shape[0]):
        for j in range(prev.shape[1]):
            block = z[i * 6:(i + 1) * 6, j * 6:(j + 1) * 6]
            good = block[np.isfinite(block)]
            if 2 * good.size >= block.size:
                assert prev[i, j] == pytest.approx(good.mean(), rel=0, abs=1e-18)
            else:
                assert np.isnan(prev[i, j])
    v = z[np.isfinite(z)]
    assert stats["valid_points"] == v.size
    assert stats["mean_m"] == pytest.approx(v.mean(), rel=0, abs=1e-18)
    assert stats["sq_m"] == pytest.approx(v.std(), rel=1e-9)
    assert stats["max_m"] - stats["min_m"] == pytest.approx(np.ptp(v), rel=1e-12)


def test_loop_bode_holds_the_open_loop(monkeypatch, tmp_path):
    from servosurf.servo import ServoLoop, load_machine
    from servosurf.viz import _servo_plots

    figs = []
    monkeypatch.setattr(_servo_plots, "save", lambda fig, path: figs.append(fig))
    loop = ServoLoop(load_machine(None).with_bandwidth(468.0))
    f = np.geomspace(50, 1e5, 400)
    fr = loop.frf(f)
    margins = loop.margins()
    _servo_plots.plot_loop_bode({"0.175 kg": fr}, tmp_path / "b.png",
                                {"0.175 kg": margins})
    ax = figs[0].axes[0]
    line = ax.get_lines()[0]
    assert "open loop" in line.get_label()
    mag = np.asarray(line.get_ydata())
    # the open loop, not a closed-loop response: integral action makes |L| large
    # well below the crossover (|T| and the disturbance FRFs stay near or below
    # 0 dB there), and it rolls off far above it
    assert mag[0] > 15.0 and mag[-1] < -40.0
    np.testing.assert_allclose(mag, 20 * np.log10(np.abs(loop.loop_gain(f))),
                               rtol=0, atol=1e-9)  # dB
    # 0 dB at the crossover the margins name (open-loop crossover bandwidth)
    k = np.nonzero((mag[:-1] >= 0) & (mag[1:] < 0))[0][0]
    assert f[k] <= margins["crossover_hz"] <= f[k + 1]
    assert margins["crossover_hz"] == pytest.approx(468.0, rel=0.01)
    notes = [t.get_text() for t in figs[0].axes[1].texts]
    assert any("crossover 468 Hz" in t and "phase margin" in t for t in notes)


def test_highpass_figure_masks_the_filter_rim(monkeypatch, tmp_path):
    """simulate's high-pass picture drops the band within half a cut-off of the
    map's edge (the Gaussian filter's end effect) and keeps the rest."""
    from servosurf.commands import simulate as cmd
    from servosurf.report._simulation import HIGH_PASS_CUTOFF

    shown = {}

    def keep(surface, path, **kw):
        shown["surface"], shown["kw"] = surface, kw
        return path

    monkeypatch.setattr(sp, "plot_map", keep)
    n, dx = 201, 0.55e-6
    y, x = (np.mgrid[0:n, 0:n] - n // 2) * dx
    r = np.hypot(x, y)
    z = np.where(r < 50e-6, 1e-10 * np.sin(x / 2e-6), np.nan)  # a lenslet's disc
    z[(r > 45e-6) & (r < 50e-6)] = -14e-9  # a rim artefact, 5 um wide
    cmd._highpass_figure({"highpass": Surface(z, dx, dx)}, tmp_path / "h.png")
    out = shown["surface"].z
    rim = 0.5 * HIGH_PASS_CUTOFF  # 6.25 um: the artefact band lies inside it
    assert np.all(np.isnan(out[r > 50e-6 - rim + dx]))
    inner = r < 50e-6 - rim - dx
    np.testing.assert_array_equal(out[inner], z[inner])
    assert shown["kw"]["robust"] == 0.5 and "rim masked" in shown["kw"]["title"]


def test_face_zarr_carries_grid_metadata(tmp_path, capsys):
    """face.zarr attributes: unit, pixel size, origin; summary Sq over every pixel."""
    import json

    zarr = pytest.importorskip("zarr")
    from servosurf.cli import main

    out = tmp_path / "face"
    assert main(["face", "flat_facing", "--radius", "60e-6", "--pitch", "2e-6",
                 "--chunk", "32", "--no-vibration", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    arr = zarr.open_array(str(out / "face.zarr"), mode="r")
    a = dict(arr.attrs)
    # face_field: 2 ceil(r / pitch) + 1 = 61 pixels, centred on the axis
    assert arr.shape == (61, 61)
    assert a["unit"] == "m" and a["dx_m"] == a["dy_m"] == 2e-6
    assert a["x0_m"] == pytest.approx(-60e-6, abs=1e-15)  # 1 fm
    assert a["y0_m"] == pytest.approx(-60e-6, abs=1e-15)
    assert a["axes"] == ["y", "x"] and a["face_radius_m"] == 60e-6
    z = np.asarray(arr[:])
    v = z[np.isfinite(z)]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["face_sq_m"] == pytest.approx(v.std(), rel=1e-6)
    assert f"{v.std() * 1e9:.3g} nm" in text and "Sq (whole face)" in text
    assert summary["zarr"] == str(out / "face.zarr")
