"""Ctrl-C (SIGINT) at the worst moments: a frame is never half-updated; `render` interrupted before
its first pass raises instead of returning an empty frame, so `gdlearn render` says so (exit 130);
an interrupted reference is not cached.

In process and without compiling a kernel (tests/experiments_fake.py's integrator; pt with its
passes replaced): the signal is sent from inside the code under test at a chosen point, so the
moment is exact, not a race."""
import os
import signal

import numpy as np
import pytest

from gdlearn.integrators import combine
from gdlearn.integrators.base import render
from experiments_fake import FakePrimal

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGINT sent to the process itself")


@pytest.fixture
def default_sigint():
    """Python's own handler, as at a terminal: a suite started in the background (`make test &`, a
    CI runner) inherits SIGINT ignored, and pytest keeps that."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_ctrl_c_while_a_pass_is_folded_in_keeps_the_frame_whole(default_sigint, monkeypatch):
    # SIGINT arrives at the end of MeanOfPasses.add of the third pass, after its sums and sample
    # counts were updated and before the frame's spp and pass count: without the deferral in
    # ProgressiveIntegrator.step the frame would show three passes' mean and say two.
    # signal.raise_signal runs Python's handler before it returns: the moment is exact.
    bookkeeping = combine._Combine._bookkeeping

    def signal_then_bookkeeping(self, res):
        if self.spp == 2:
            signal.raise_signal(signal.SIGINT)
        bookkeeping(self, res)

    monkeypatch.setattr(combine._Combine, "_bookkeeping", signal_then_bookkeeping)
    integ = FakePrimal(seed=4, h=2, w=3)
    frame = render(integ, passes=10)
    assert frame.interrupted and frame.passes == 3 and frame.spp == 3
    # the mean of the three passes, recomputed independently of the combine's bookkeeping
    passes = [FakePrimal(seed=4, h=2, w=3).render_pass(i).images["primal"] for i in range(3)]
    assert np.allclose(frame.primal, np.mean(passes, axis=0), rtol=1e-12)
    # Python's handler is back: a later Ctrl-C is a KeyboardInterrupt again
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_render_command_interrupted_before_the_first_pass_writes_nothing(default_sigint, monkeypatch,
                                                                         tmp_path, capsys):
    # The first pass is interrupted: nothing was accumulated. The command must say so and exit 130,
    # not fail on an empty frame's `frame.primal` with a KeyError (exit 1; seen on a loaded CI machine).
    from gdlearn.cli import main
    from gdlearn.integrators.path import pt

    def interrupted(self, pass_index):
        raise KeyboardInterrupt

    monkeypatch.setattr(pt.PathTracer, "compile", lambda self: 0.0)
    monkeypatch.setattr(pt.PathTracer, "render_pass", interrupted)
    out = tmp_path / "x.npy"
    scene = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes",
                         "cornell-box.xml")
    assert main(["render", scene, "--spp", "4", "--set", "res=8", "--out", str(out), "--no-progress"]) == 130
    assert "interrupted before the first pass; nothing written" in capsys.readouterr().err
    assert not out.exists()


class _InterruptedAt(FakePrimal):
    """Ctrl-C (as Python raises it) inside pass ``at``."""

    at = 0

    def render_pass(self, i):
        if i == self.at:
            raise KeyboardInterrupt
        return super().render_pass(i)


def test_render_interrupted_in_its_first_pass_raises():
    # nothing was accumulated, so there is no frame to return: the interrupt goes on to the caller
    # (returned, the empty frame failed on `frame.primal` with a KeyError wherever it was used)
    with pytest.raises(KeyboardInterrupt):
        render(_InterruptedAt(seed=1, h=2, w=3), passes=10)
    later = type("Later", (_InterruptedAt,), {"at": 2})(seed=1, h=2, w=3)
    frame = render(later, passes=10)
    assert frame.interrupted and frame.passes == 2 and np.isfinite(frame.primal).all()


def test_an_interrupted_reference_is_not_cached(tmp_path, monkeypatch):
    # a reference stopped early has fewer samples than its cache key says: caching it would hand
    # every later study a noisier reference under the full budget's name
    from gdlearn.experiments import references as R
    from gdlearn.teaching.toy import ToyPrimal, ToyScene

    class Stopped(ToyPrimal):
        def render_pass(self, i):
            if i == 3:
                raise KeyboardInterrupt
            return super().render_pass(i)

    monkeypatch.setenv("GDLEARN_CACHE", str(tmp_path))
    with pytest.raises(KeyboardInterrupt):
        R.render_reference(ToyScene(10, 6), Stopped, spp=64, spp_per_pass=8)
    assert not list(tmp_path.rglob("*.npz"))
    assert R.render_reference(ToyScene(10, 6), ToyPrimal, spp=64, spp_per_pass=8).spp == 64
    assert len(list(tmp_path.rglob("*.npz"))) == 1
