"""Scenes built directly from :mod:`gdlearn.scene.model` for the path-tracer tests.

They do not go through the XML loader on purpose: the renderer's tests must not fail because of a
loader bug (the loader has its own tests, and the Mitsuba cross-checks cover the XML road).
"""
import math

import numpy as np

from gdlearn.scene.model import (BSDF, Emitter, Film, Integrator, Medium, Scene, Sensor, Shape, rgb)


def translate(x=0.0, y=0.0, z=0.0):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def scale(x, y=None, z=None):
    return np.diag([x, x if y is None else y, x if z is None else z, 1.0])


def rotate(axis, angle_deg):
    """Mitsuba's rotate (right-handed, degrees)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    x, y, z = a
    m = np.eye(4)
    m[:3, :3] = [[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                 [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                 [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]]
    return m


def chain(*ms):
    """Mitsuba composes transform children in order: the first is applied first."""
    out = np.eye(4)
    for m in ms:
        out = m @ out
    return out


def lookat(origin, target, up):
    o, t, u = (np.asarray(v, dtype=float) for v in (origin, target, up))
    d = (t - o) / np.linalg.norm(t - o)
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    nu = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, nu, d, o
    return m


def cornell_box(res=32, max_depth=8, integrator="path", medium=None):
    """Mitsuba's cornell box as in scenes/cornell-box.xml; ``medium`` fills it (camera + all shapes)."""
    white = BSDF("diffuse", reflectance=rgb(0.885809, 0.698859, 0.666422))
    green = BSDF("diffuse", reflectance=rgb(0.105421, 0.37798, 0.076425))
    red = BSDF("diffuse", reflectance=rgb(0.570068, 0.0430135, 0.0443706))
    sensor = Sensor(fov=39.3077, fov_axis="smaller", to_world=lookat((0, 0, 3.9), (0, 0, 0), (0, 1, 0)),
                    film=Film(res, res, "box"), spp=16, medium=medium)
    sh = [
        Shape("rectangle", chain(scale(0.23, 0.19, 0.19), rotate((1, 0, 0), 90), translate(0, 0.99, 0.01)), white,
              emitter=Emitter("area", radiance=rgb(18.387, 13.9873, 6.75357))),
        Shape("rectangle", chain(rotate((1, 0, 0), -90), translate(0, -1, 0)), white),
        Shape("rectangle", chain(rotate((1, 0, 0), 90), translate(0, 1, 0)), white),
        Shape("rectangle", translate(0, 0, -1), white),
        Shape("rectangle", chain(rotate((0, 1, 0), -90), translate(1, 0, 0)), green),
        Shape("rectangle", chain(rotate((0, 1, 0), 90), translate(-1, 0, 0)), red),
        Shape("cube", chain(scale(0.3), rotate((0, 1, 0), -17), translate(0.335, -0.7, 0.38)), white),
        Shape("cube", chain(scale(0.3, 0.61, 0.3), rotate((0, 1, 0), 18.25), translate(-0.33, -0.4, -0.28)), white),
    ]
    if medium is not None:
        for s in sh:
            s.interior = s.exterior = medium
    return Scene(Integrator(integrator, max_depth), sensor, sh)


def furnace(rho, le, res=8, max_depth=-1, rr_depth=5, medium=None):
    """Camera at the centre of a closed sphere of albedo rho that emits le on its inside.

    The sphere's normals are flipped so they face the camera: a one-sided emitter and a one-sided
    diffuse BSDF then both act on the inside. Every path sees L = le / (1 - rho). With ``medium``
    the sphere is filled with it (and the camera sits in it); since the normals point inwards, the
    inside is the sphere's *exterior* side in Mitsuba's convention."""
    sensor = Sensor(fov=60.0, to_world=lookat((0, 0, 0), (0, 0, 1), (0, 1, 0)), film=Film(res, res, "box"),
                    medium=medium)
    s = Shape("sphere", scale(1.0), BSDF("diffuse", reflectance=rgb(rho)),
              emitter=Emitter("area", radiance=rgb(le)), flip_normals=True, interior=None, exterior=medium)
    return Scene(Integrator("volpath" if medium is not None else "path", max_depth, rr_depth), sensor, [s])


def single_scatter_box(sigma_t, albedo, g, light=(0.3, 0.2, 0.1), intensity=1.0, max_depth=-1):
    """A 1x1-pixel camera at (0, 0, 3) looking down -z with a tiny field of view (all its rays are
    the z axis to ~1e-5) through a null-bounded medium cube [-1, 1]^3 with a point light inside."""
    med = Medium(sigma_t=rgb(*sigma_t), albedo=rgb(albedo), phase="hg" if g else "isotropic", g=g)
    sensor = Sensor(fov=1e-3, to_world=lookat((0, 0, 3), (0, 0, 0), (0, 1, 0)), film=Film(1, 1, "box"))
    cube = Shape("cube", np.eye(4), BSDF("null"), interior=med, exterior=None)
    lamp = Emitter("point", intensity=rgb(intensity), position=np.array(light, dtype=float))
    return Scene(Integrator("volpath", max_depth), sensor, [cube], emitters=[lamp])
