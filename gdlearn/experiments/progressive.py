"""The progressive runner: render for a time or pass budget, keep snapshots, time every stage.

The papers compare estimators on *convergence plots*: error against render time, with images output
at regular points of one long progressive run (Hua et al. 2017 §5: "We output renderings after every five
photon passes and collect the images for error measurement"; Gruson et al. 2018 Fig. 7). :func:`run` does this
for any :class:`~gdlearn.integrators.base.ProgressiveIntegrator`:

* the JIT is warmed first and its time is kept apart (``compile_seconds``), never in the curves;
* snapshots are taken at geometrically spaced times (or pass counts), evenly spread on the log axis
  of the plot;
* a gradient-domain snapshot is reconstructed with the chosen solver (:mod:`.solvers`) and the
  reconstruction is timed as its own stage. A snapshot's time is the render time so far plus *its*
  reconstruction: a user who stopped there would reconstruct once, so earlier snapshots'
  reconstructions are not charged to later ones;
* the stage timings of the frame (``trace``, ``shift``, ``gather``, ...) are copied into each
  snapshot, so stage-cost bars can be drawn at any point of the run.

Determinism: the image after k passes depends only on the integrator's seed (counter-based random
numbers), so a *pass* budget gives bit-identical snapshots on any machine or executor; a *time* budget
gives identical images at equal pass counts, but how many passes fit depends on the machine.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from gdlearn.experiments import metrics
from gdlearn.experiments.solvers import resolve


@dataclass
class Snapshot:
    """One point of a convergence curve."""
    passes: int
    spp: int
    render_seconds: float            # wall time in passes so far, JIT compile excluded
    reconstruct_seconds: float       # time of this snapshot's reconstruction (0 for primal images)
    timings: dict[str, float]        # per-stage seconds so far (compile excluded), + 'reconstruct'
    stats: dict[str, int]
    image: np.ndarray | None = None  # the final estimate (reconstructed for gradient methods)
    primal: np.ndarray | None = None  # the primal estimate of a gradient method (None otherwise)
    errors: dict[str, float] = field(default_factory=dict)

    @property
    def seconds(self) -> float:
        """The time this image cost: rendering so far plus its reconstruction."""
        return self.render_seconds + self.reconstruct_seconds


@dataclass
class Run:
    """A progressive run: its snapshots in order, the JIT compile time, whether it was interrupted."""
    snapshots: list[Snapshot]
    compile_seconds: float
    interrupted: bool = False

    @property
    def final(self) -> Snapshot:
        return self.snapshots[-1]


def pass_schedule(passes: int, count: int = 12) -> list[int]:
    """Up to ``count`` pass counts, geometrically spaced from 1 to ``passes`` (both included)."""
    if passes < 1:
        raise ValueError(f"passes={passes} must be >= 1")
    return sorted(set(int(round(p)) for p in np.geomspace(1, passes, max(count, 1))) | {passes})


def time_schedule(seconds: float, count: int = 12, first: float | None = None) -> list[float]:
    """``count`` snapshot times, geometrically spaced from ``first`` (default seconds / 100) to
    ``seconds``."""
    if not seconds > 0:
        raise ValueError(f"seconds={seconds} must be > 0")
    first = seconds / 100.0 if first is None else first
    return [float(t) for t in np.geomspace(min(first, seconds), seconds, max(count, 2))]


def _measure(image, reference, reference_floor=None) -> dict[str, float]:
    out = {"relmse": metrics.relmse(image, reference),
           "relmse_trimmed": metrics.relmse_trimmed(image, reference),
           "mse": metrics.mse(image, reference)}
    if reference_floor is not None:
        out["relmse_floor"] = float(reference_floor)
    return out


def snapshot(frame, solver=None, solver_options=None, reference=None, keep_image=True,
             reference_floor=None) -> Snapshot:
    """Reconstruct (timed) and measure one frame. A solver applies only to frames with gradients:
    primal-only frames pass through, so one solver can serve a study mixing both kinds."""
    fn = resolve(solver) if frame.gx is not None else None
    t0 = time.perf_counter()
    image = frame.primal if fn is None else fn(frame, **(solver_options or {}))
    rec = time.perf_counter() - t0 if fn is not None else 0.0
    bad = ~np.isfinite(image)
    stats = dict(frame.stats)
    if bad.any():                     # a solver blew up: count it, never let NaN into a plot
        stats["nonfinite_reconstructed"] = stats.get("nonfinite_reconstructed", 0) + int(bad.sum())
        image = np.where(bad, 0.0, image)
    timings = {k: v for k, v in frame.timings.items() if k != "compile"}
    if fn is not None:
        timings["reconstruct"] = rec
    snap = Snapshot(frame.passes, frame.spp, frame.elapsed, rec, timings, stats)
    if reference is not None:
        snap.errors = _measure(image, reference, reference_floor)
        if fn is not None:
            snap.errors["relmse_primal"] = metrics.relmse(frame.primal, reference)
    if keep_image:
        snap.image = np.array(image, dtype=np.float64)
        snap.primal = np.array(frame.primal) if fn is not None else None
    return snap


def warm_solver(solver) -> float:
    """Call ``solver`` once on a tiny synthetic frame so its JIT compilation (numba solvers compile
    per array type, not per size) is counted as compile time, not as reconstruction time of the
    first snapshot. Returns the seconds it took (0 without a solver)."""
    fn = resolve(solver)
    if fn is None:
        return 0.0
    from gdlearn.integrators.base import Frame
    rng = np.random.default_rng(0)
    imgs = {n: rng.random((4, 4, 3)) for n in ("primal", "gx", "gy")}
    halves = {n: (v, 0.5 * v) for n, v in imgs.items()}
    t0 = time.perf_counter()
    fn(Frame(2, 2, imgs, halves, {}, {}, 0.0))
    return time.perf_counter() - t0


def _reserve(snaps, seconds) -> float:
    """Time to keep for the final reconstruction under a time budget. Its cost hardly depends on
    the pass count, so the fastest snapshot reconstruction so far estimates it, least inflated by
    other processes competing for the cores; a single measurement is not trusted (one scheduling
    hiccup would end the run), and never more than half the budget is reserved."""
    if len(snaps) < 2:
        return 0.0
    return min(min(s.reconstruct_seconds for s in snaps), 0.5 * seconds)


def run(integrator, *, seconds: float | None = None, passes: int | None = None, count: int = 12,
        first: float | None = None, solver=None, solver_options=None, reference=None,
        reference_floor=None, keep_images: str = "final", callback=None) -> Run:
    """Render progressively for ``seconds`` of wall time (compile excluded) or ``passes`` passes.

    With a time budget and a solver, rendering stops when the time so far plus the expected
    reconstruction time (:func:`!_reserve`) reaches ``seconds``, so the final image -- render plus
    reconstruction -- costs about ``seconds``, as for a primal method.

    Snapshots follow :func:`time_schedule` or :func:`pass_schedule` (``count`` points); the last one
    is always the end of the run. ``keep_images`` is ``"final"``, ``"all"`` or ``"none"``: which
    snapshots keep their images (errors against ``reference`` are computed for all of them).
    ``callback(snapshot)`` is called after each snapshot. Ctrl-C ends the run early with a final
    snapshot of what was accumulated and ``interrupted=True``.
    """
    if (seconds is None) == (passes is None):
        raise ValueError("give exactly one budget: seconds=... (equal time) or passes=... (equal samples)")
    if keep_images not in ("final", "all", "none"):
        raise ValueError(f"keep_images={keep_images!r}: use 'final', 'all' or 'none'")
    solver = resolve(solver)          # fail on an unknown solver before compiling anything
    compile_s = integrator.warmup() + warm_solver(solver)
    marks = pass_schedule(passes, count) if passes is not None else time_schedule(seconds, count, first)
    snaps: list[Snapshot] = []
    interrupted = False
    frame = None
    k = 0                             # index of the next snapshot mark

    def take(fr, last=False):
        keep = keep_images == "all" or (last and keep_images == "final")
        snaps.append(snapshot(fr, solver, solver_options, reference, keep, reference_floor))
        if callback is not None:
            callback(snaps[-1])

    try:
        while True:
            frame = integrator.step()
            now = frame.passes if passes is not None else frame.elapsed
            reserve = _reserve(snaps, seconds) if passes is None else 0.0
            done = now >= (passes if passes is not None else seconds - reserve)
            if k < len(marks) and now >= marks[k] and not done:
                take(frame)
                while k < len(marks) and marks[k] <= now:   # skip marks this pass already passed
                    k += 1
            if done:
                break
    except KeyboardInterrupt:
        interrupted = True
        frame = integrator.frame(interrupted=True)
    if frame is not None and frame.passes > 0:
        take(frame, last=True)
    return Run(snaps, float(compile_s), interrupted)
