"""The progressive runner on a fake integrator with a known image (tests/experiments_fake.py)."""
import numpy as np
import pytest

from experiments_fake import PASS_SECONDS, SIGMA, FakeGradient, FakePrimal, VirtualClock, fake_solver, truth
from gdlearn.experiments import progressive as P
from gdlearn.experiments.metrics import RELMSE_EPS


def test_schedules_are_geometric_and_monotone():
    ps = P.pass_schedule(100, 8)
    assert ps[0] == 1 and ps[-1] == 100 and all(b > a for a, b in zip(ps, ps[1:]))
    assert P.pass_schedule(3, 12) == [1, 2, 3]
    ts = P.time_schedule(2.0, 5)
    assert ts[0] == pytest.approx(0.02) and ts[-1] == pytest.approx(2.0)
    ratios = np.diff(np.log(ts))
    assert np.allclose(ratios, ratios[0])
    with pytest.raises(ValueError):
        P.pass_schedule(0)


def test_pass_budget_snapshots_and_compile_apart():
    run = P.run(FakePrimal(seed=1), passes=40, count=6, reference=truth())
    assert [s.passes for s in run.snapshots] == P.pass_schedule(40, 6)
    secs = [s.seconds for s in run.snapshots]
    assert all(b > a for a, b in zip(secs, secs[1:]))          # monotone snapshot times
    assert run.compile_seconds == 0.01                         # the fake's warm-up, kept apart
    assert all("compile" not in s.timings for s in run.snapshots)
    assert run.snapshots[-1].timings["trace"] == pytest.approx(40 * 0.002)
    assert run.final.image is not None and all(s.image is None for s in run.snapshots[:-1])
    assert run.final.spp == 40 and run.final.stats["paths"] == 40 * 48


@pytest.fixture
def clock(monkeypatch):
    """Virtual time for the time-budget tests (experiments_fake.VirtualClock): their assertions
    about seconds then hold on a loaded machine too, where a real 2 ms sleep may take 20 ms."""
    import time
    c = VirtualClock()
    monkeypatch.setattr(time, "perf_counter", c.perf_counter)
    monkeypatch.setattr(time, "sleep", c.sleep)
    return c


def test_time_budget_is_respected(clock):
    run = P.run(FakePrimal(seed=2), seconds=0.06, count=5, keep_images="none")
    r = [s.render_seconds for s in run.snapshots]
    assert all(b > a for a, b in zip(r, r[1:]))
    assert r[-1] >= 0.06 and len(run.snapshots) <= 5
    assert r[-1] < 0.06 + PASS_SECONDS + 1e-12          # virtual time: it stops within one pass
    assert run.final.image is None


def test_same_seed_same_curve_other_seed_other_curve():
    a = P.run(FakePrimal(seed=5), passes=20, reference=truth(), keep_images="all")
    b = P.run(FakePrimal(seed=5), passes=20, reference=truth(), keep_images="all")
    c = P.run(FakePrimal(seed=6), passes=20, reference=truth())
    assert [s.errors["relmse"] for s in a.snapshots] == [s.errors["relmse"] for s in b.snapshots]
    assert all(np.array_equal(x.image, y.image) for x, y in zip(a.snapshots, b.snapshots))
    assert a.final.errors["relmse"] != c.final.errors["relmse"]


def test_relmse_follows_the_variance_of_the_mean():
    """relMSE of N passes of truth + N(0, SIGMA^2) noise has expectation
    mean(SIGMA^2 / N / (T^2 + eps)) -- computed here from the fake's parameters, not by the runner."""
    h, w, n = 30, 40, 16
    t = truth(h, w)
    run = P.run(FakePrimal(seed=3, h=h, w=w), passes=n, reference=t, count=3)
    expected = np.mean(SIGMA ** 2 / n / (t * t + RELMSE_EPS))
    # 3600 chi-square(1) terms (weighted): relative std <~ sqrt(2/3600) * 2 = 5 %; 20 % is 4 sigma.
    assert run.final.errors["relmse"] == pytest.approx(expected, rel=0.2)
    # the 1/N law: from 1 to 16 passes the error drops ~16x (each end within its own 20 %)
    assert run.snapshots[0].errors["relmse"] / run.final.errors["relmse"] == pytest.approx(16, rel=0.45)


def test_solver_is_timed_and_applies_to_gradients_only():
    g = P.run(FakeGradient(seed=1), passes=10, count=3, reference=truth(), solver=fake_solver)
    s = g.final
    assert s.reconstruct_seconds > 0 and "reconstruct" in s.timings
    assert s.seconds == pytest.approx(s.render_seconds + s.reconstruct_seconds)
    assert "relmse_primal" in s.errors
    # averaging with an almost exact neighbour estimate lowers the error (noise of SIGMA_G << SIGMA)
    assert s.errors["relmse"] < s.errors["relmse_primal"]
    np.testing.assert_array_equal(s.primal.shape, s.image.shape)
    p = P.run(FakePrimal(seed=1), passes=10, count=3, solver=fake_solver)
    assert p.final.reconstruct_seconds == 0.0 and "reconstruct" not in p.final.timings


def test_bad_arguments_fail_before_rendering():
    with pytest.raises(ValueError, match="exactly one budget"):
        P.run(FakePrimal(), passes=3, seconds=1.0)
    with pytest.raises(ValueError, match="unknown solver"):
        P.run(FakePrimal(), passes=3, solver="l3")


class _Interrupted(FakePrimal):
    def render_pass(self, i):
        if i == 5:
            raise KeyboardInterrupt
        return super().render_pass(i)


def test_ctrl_c_keeps_what_was_accumulated():
    run = P.run(_Interrupted(seed=1), passes=50, reference=truth())
    assert run.interrupted and run.final.passes == 5 and run.final.image is not None


def _slow_solver(frame):
    import time
    time.sleep(0.1)
    return frame.primal


def test_time_budget_reserves_the_final_reconstruction(clock):
    run = P.run(FakeGradient(seed=1), seconds=0.4, count=4, first=0.05, solver=_slow_solver)
    snaps = run.snapshots
    reserve = min(s.reconstruct_seconds for s in snaps[:-1])
    assert len(snaps) >= 3 and reserve == pytest.approx(0.1)     # the solver's virtual 0.1 s
    # rendering stopped once render time + reserve reached the budget, not at the budget itself
    # (a fake pass takes 2 ms, far less than the 0.1 s margin)
    assert 0.4 - reserve - 1e-12 <= snaps[-1].render_seconds < 0.4
    assert snaps[-1].render_seconds < 0.4 - reserve + PASS_SECONDS + 1e-12   # and within one pass of it
    assert P._reserve(snaps[:1], 0.4) == 0.0          # one measurement is not trusted
    assert P._reserve(snaps, 0.1) == 0.05             # never more than half the budget
