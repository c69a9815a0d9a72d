"""Record (or check) every integrator's buffers on every shipped scene at a tiny size.

The arrays in ``tests/golden/*.npz`` were recorded before the code moved into its present layout;
``tests/test_golden_outputs.py`` renders the same configurations and asks for identical counters
and buffers equal to rounding (1e-12 of their scale: numba's code for the host CPU sums a few terms
in a different order on AVX-512 than on AVX2). A refactoring that changes one random number fails it.
Re-record only when a change is meant to alter results (a bug fix, new random numbers):

    python tests/golden/record.py            # rewrites tests/golden/*.npz
    python tests/golden/record.py spot-medium   # only the stems that start with these names

Re-record only the stems the change was meant to alter: the others would pick up this machine's
last-bit differences (see the test's module docstring) and hide them in an unrelated commit.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
SCENES = ("cornell-box", "fog-box", "mesh", "caustics-box", "caustic-closeup", "spot-medium")
#: gpt's policies that run on every scene (the manifold one only where the walk can run)
GPT_SHIFTS = ("replay", "replay+reconnection", "halfvector+reconnection", "halfvector+replay+reconnection",
              "halfvector+reconnection+manifold")
RES, SPP_PER_PASS, PASSES, SEED = 12, 2, 2, 3


def configurations():
    """(file stem, scene name, integrator name, options) for every recorded run."""
    for scene in SCENES:
        yield f"{scene}__pt", scene, "pt", {}
        if scene == "cornell-box":
            yield f"{scene}__pt-scalar", scene, "pt", {"packets": False}
        yield f"{scene}__gpt-replay", scene, "gpt-replay", {}
        yield f"{scene}__gpt-default", scene, "gpt", {}
        media = scene in ("fog-box", "spot-medium")
        for shift in GPT_SHIFTS:
            if media and shift.endswith("manifold"):
                continue          # refused in media (a ValueError, tested elsewhere)
            yield f"{scene}__gpt_shift-{shift}", scene, "gpt", {"shift": shift}


def run(scene: str, integrator: str, options: dict) -> dict[str, np.ndarray]:
    import gdlearn.scene as gs
    from gdlearn.integrators import make, render

    sc = gs.load(str(ROOT / "scenes" / f"{scene}.xml"), res=RES)
    integ = make(integrator, sc, seed=SEED, spp_per_pass=SPP_PER_PASS, **options)
    frame = render(integ, spp=SPP_PER_PASS * PASSES)
    out = {f"buf_{k}": v for k, v in frame.buffers().items()}
    for k, v in frame.stats.items():
        out[f"stat_{k}"] = np.asarray(v)
    return out


def main(argv=None) -> int:
    prefixes = tuple(argv or ())
    for stem, scene, integrator, options in configurations():
        if prefixes and not stem.startswith(prefixes):
            continue
        arrays = run(scene, integrator, options)
        np.savez_compressed(HERE / f"{stem}.npz", **arrays)
        print(stem, len(arrays), "arrays", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
