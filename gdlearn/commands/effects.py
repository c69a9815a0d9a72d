"""``gdlearn effects SCENE [--effects LIST]``: print the effects plan of a scene and its reasons.

Which light transport the scene can show (direct light, interreflection, glossy and specular
chains, caustics, single and multiple scattering, volume caustics), which of it is rendered (the
scene file's ``<default name="effects">`` or ``--effects``), and why each code path (volume code,
next-event estimation, MIS, Russian roulette, specular chains, photons) runs or not.
See :mod:`gdlearn.scene.effects`.
"""
from __future__ import annotations

import sys


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("effects", help="print which light transport a scene can show and what runs",
                              description=__doc__.splitlines()[0])
    p.add_argument("scene", help="scene file (Mitsuba 3 XML subset, see scenes/README.md)")
    p.add_argument("--effects", default=None,
                   help="comma list of effects or groups (direct, volume, surface, all), "
                        "e.g. direct,single-scattering; default: the scene file's request, else all")
    p.add_argument("--max-depth", type=int, default=None, help="override the integrator's max_depth")
    p.set_defaults(func=run)


def run(args) -> int:
    from gdlearn.scene.effects import EffectsError, plan
    from gdlearn.scene.load import load

    scene = load(args.scene)
    if args.max_depth is not None:
        scene.integrator.max_depth = args.max_depth
    try:
        p = plan(scene, args.effects)
    except EffectsError as err:
        print(f"gdlearn effects: {err}", file=sys.stderr)
        return 2
    for w in scene.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(p.describe())
    return 0
