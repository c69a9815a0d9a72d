"""The figures draw what the records say (fitted slope in the legend, floor line, captions)."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from experiments_fake import FakeGradient, FakePrimal, fake_solver, truth  # noqa: E402
from gdlearn.experiments import plots  # noqa: E402
from gdlearn.experiments import study as S  # noqa: E402


@pytest.fixture(scope="module")
def study():
    return S.equal_time([FakePrimal, S.Method("fgpt", FakeGradient, fake_solver)], [None],
                        passes=16, seeds=2, count=5, references={"none": truth()},
                        executor="serial")


def test_convergence_legend_has_slope_and_floor(study):
    for r in study.records:
        r["relmse_floor"] = 1e-3                      # pretend a noisy reference
    ax = plots.convergence(study)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(lbl.startswith("fake-pt (slope -") for lbl in labels)
    assert "reference noise floor" in labels
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    # one line per (method, seed) plus the floor
    assert len(ax.get_lines()) == 2 * 2 + 1


def test_image_grid_captions_carry_relmse(study):
    img = study.images[("fake-pt", "none", 0)]
    axes = plots.image_grid({"pt": img}, truth())
    from gdlearn.experiments.metrics import relmse
    assert f"relMSE {relmse(img, truth()):.3g}" in axes[0].get_title()
    assert axes[1].get_title() == "reference"


def test_every_panel_draws(study, tmp_path):
    plots.stage_bars(study)
    plots.ratio_bars(study, "fake-pt")
    plots.time_to_reach_bars(study, 0.5)
    plots.error_maps({"pt": study.images[("fake-pt", "none", 0)]}, truth())
    fig = plots.summary(study, reference=truth())
    fig.savefig(tmp_path / "s.png")
    assert (tmp_path / "s.png").stat().st_size > 10_000
    assert np.all(plots.display(np.array([-1.0, 0.25, 4.0])) == np.array([0.0, 0.25 ** (1 / 2.2), 1.0]))
