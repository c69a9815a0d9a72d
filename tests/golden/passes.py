"""Record (or check) the photon estimators' fast camera passes against the kernels they replaced.

Each fast pass -- GPM's (``gpm_gather.gpm_rows``), the volumetric full images' surface pass
(``gvol_surface.surface_rows``), G-VPM's (``gvpm_gather.gvpm_rows``) and G-BRE's
(``gbre_gather.gbre_rows``) -- sums the same terms in the same order as the straightforward kernel
it replaced, kept in ``tests/_*_reference.py``: one photon at a time, four calls of the shift, a
buffer write per term. The arrays in ``tests/golden/passes/`` are the *reference* kernels'
buffers, recorded by this script on the same photons and radii the fast kernel then gathers;
``tests/test_photon_fast_passes.py`` runs the fast kernel and applies ``tests/golden/gate.py``
(counts identical, floating point to 1e-12 of a buffer's scale). On the recording machine the fast
kernels reproduced the recordings bit for bit (2026-12-07).

Recorded, not compared live: compiling the four reference kernels took about 8 minutes of the
suite's two workers (2026-12-07), for kernels that never change. Re-record when a change is meant
to alter what a pass computes or what it is given (photon tracing, random numbers, radii), in the
same commit, and say why. The reference kernels must still run then: that is when to repair them.

    python tests/golden/passes.py              # re-record every case (runs the reference kernels)
    python tests/golden/passes.py gbre         # only the stems that start with these names
"""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np

from gate import mismatch       # tests/golden/ is on the path: this script's folder, or the test's insert

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
OUT = HERE / "passes"

GBRE_VARIANTS = {"3d-mixed": dict(kernel="3d", shift="mixed"), "3d-simple": dict(kernel="3d", shift="simple"),
                 "2d": dict(kernel="2d"), "3d-mixed-nosubsets": dict(kernel="3d", shift="mixed", subsets=False),
                 "2d-nosubsets": dict(kernel="2d", subsets=False)}


def cases(family: str | None = None) -> list[tuple[str, str, str, dict]]:
    """(file stem, family, scene name, options) of every recorded pass (of ``family``'s only)."""
    out = [(f"gpm__{s}", "gpm", s, {}) for s in ("cornell-box", "caustics-box", "mirror-caustic")]
    out += [(f"gvol_surface__{s}", "gvol_surface", s, {}) for s in ("fog-box", "spot-medium", "volume-caustic")]
    for s in ("fog-box", "spot-medium"):
        out += [(f"gvpm__{s}__{shift}", "gvpm", s, {"shift": shift}) for shift in ("mixed", "simple")]
        out += [(f"gbre__{s}__{name}", "gbre", s, kw) for name, kw in GBRE_VARIANTS.items()]
    return [c for c in out if family in (None, c[1])]


def check(stem: str, family: str, scene: str, options: dict) -> dict[str, np.ndarray]:
    """Run the fast kernel on a recorded case and assert it reproduces the recording (the gate of
    tests/golden/gate.py, every buffer). Returns the recording, for the caller's coverage checks."""
    want = recorded(stem)
    got = run(family, scene, options)
    assert sorted(got) == sorted(want), "a buffer appeared or disappeared"
    for name, w in want.items():
        why = mismatch(w, got[name])
        assert why is None, f"{stem}: {name} differs from the reference kernel's recording ({why})"
    return want


def _scene(name: str, res: int):
    from gdlearn.scene.load import load
    return load(str(ROOT / "scenes" / f"{name}.xml"), res=res)


def _gpm(scene: str, which: str):
    """GPM's pass 1 on the Cornell box (reconnections only), the caustics box and the mirror caustic
    (the manifold walk's branch)."""
    from gdlearn.integrators import make
    from gdlearn.integrators.photon import gpm_gather as gg
    g = make("gpm", _scene(scene, 14), seed=7, photons_per_pass=4000)
    g.render_pass(0)                                    # the progressive radii of pass 0, reduced
    lp, grids = g.build(g.trace_photons(1))
    rows = gg.gpm_rows if which == "fast" else _reference("gpm").reference_rows
    out = gg.allocate(g.height, g.width)
    with g.setup.parallel(g.height):
        rows(g.setup.sa, lp, grids, g.mtab, g.gather_params, g.seed, 2, np.sqrt(g.r2), out)
    return out


def _gvol_surface(scene: str, which: str):
    """The surface pass of G-VPM's full image: the fog box (surfaces seen and lit through a medium
    filling the scene), the spot medium (photon edges through a smoke block's null faces, medium
    parents), the volume caustic (glass above the medium)."""
    from gdlearn.integrators import make
    from gdlearn.integrators.photon import gpm_gather as gg
    from gdlearn.integrators.photon import gvol_surface as gs
    g = make("gvpm", _scene(scene, 14), seed=5, photons_per_pass=6000, transport="all")
    g.render_pass(0)
    lp = g.trace_photons(1)
    _, sgrids, _, _ = g.build(lp)
    rows = gs.surface_rows if which == "fast" else _reference("gvol_surface").reference_rows
    out = gg.allocate(g.height, g.width)
    with g.setup.parallel(g.height):
        rows(g.setup.sa, lp, sgrids, g.mtab, g.gather_params, g.seed, 2, np.sqrt(g.r2), out)
    return out


def _gvpm(scene: str, which: str, shift: str):
    """G-VPM's medium pass on the fog box (analytic recorded edges) and the spot medium (every
    reconnection walks through the block's null top), at VPM's default radius, not gvpm's smaller
    one: the comparison must see many shifts of every kind."""
    from gdlearn.integrators import make
    from gdlearn.integrators.photon import gvpm_gather as gg
    g = make("gvpm", _scene(scene, 12), seed=5, photons_per_pass=3000, transport="media", shift=shift,
             volume_radius_scale=1.0)
    g.render_pass(0)
    lp = g.trace_photons(1)
    _, _, vgrids, _ = g.build(lp)
    out = gg.allocate(g.height, g.width)
    with g.setup.parallel(g.height):
        if which == "fast":         # no specular parent in these scenes: the manifold branch is never taken
            gg.gvpm_rows(g.setup.sa, lp, vgrids, g.mtab, g.gather_params, g.gv, g.seed, 2, g.rv, out)
        else:
            _reference("gvpm").reference_rows(g.setup.sa, lp, vgrids, g.gather_params, g.gv, g.seed, 2, g.rv, out)
    return out


def _gbre(scene: str, which: str, **kw):
    """G-BRE's medium pass (pass 1: the global schedule already reduced), the 3D kernel with either
    shift and the 2D one, photon subsets on and off, at the BRE's default radius."""
    from gdlearn.integrators import make
    from gdlearn.integrators.photon import gbre_gather as gb
    from gdlearn.integrators.photon import gvpm_gather as gg
    g = make("gbre", _scene(scene, 12), seed=5, photons_per_pass=3000, transport="media", volume_radius_scale=1.0,
             **kw)
    g.render_pass(0)
    lp = g.trace_photons(1)
    _, bbhs, r, _ = g.build(lp)
    out = gg.allocate(g.height, g.width)
    with g.setup.parallel(g.height):
        if which == "fast":
            gb.gbre_rows(g.setup.sa, lp, bbhs, g.mtab, float(r), g.gather_params, g.gp, g.wsub, g.seed, 2, out)
        else:
            _reference("gbre").reference_rows(g.setup.sa, lp, bbhs, float(r), g.gather_params, g.gp, g.wsub,
                                              g.seed, 2, out)
    return out


def _reference(family: str):
    """The reference kernel's module, tests/_<family>_reference.py (compiled only to record)."""
    if str(HERE.parent) not in sys.path:
        sys.path.insert(0, str(HERE.parent))
    return importlib.import_module(f"_{family}_reference")


PASSES = {"gpm": _gpm, "gvol_surface": _gvol_surface, "gvpm": _gvpm, "gbre": _gbre}


def run(family: str, scene: str, options: dict, which: str = "fast") -> dict[str, np.ndarray]:
    """The buffers of one pass by the ``"fast"`` kernel or the ``"reference"`` one (``which``), by field
    name."""
    out = PASSES[family](scene, which, **options)
    return dict(zip(out._fields, out))


def recorded(stem: str) -> dict[str, np.ndarray]:
    """The recording of case ``stem``, by field name."""
    with np.load(OUT / f"{stem}.npz") as z:
        return {k: z[k] for k in z.files}


def main(argv=None) -> int:
    prefixes = tuple(argv or ())
    OUT.mkdir(exist_ok=True)
    for stem, family, scene, options in cases():
        if prefixes and not stem.startswith(prefixes):
            continue
        np.savez_compressed(OUT / f"{stem}.npz", **run(family, scene, options, which="reference"))
        print(stem, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
