"""The figure helpers of the chapter "Shift mappings" (gdlearn.teaching.figures.shifts, shift_checks): the
section scene's ray casting by hand, base paths that obey the specular laws, offset paths that are
what the policies say (shared vertices after a reconnection, copied half vectors, manifold chains
that obey Snell's law and end on the base's light vertex), zero failures for a zero shift, and the
tabulated Jacobian check. Every expected value is computed here, independently of the module."""

import numpy as np
import pytest

from gdlearn.teaching.figures import shift_checks as C
from gdlearn.teaching.figures import shifts as S
GLASS, MIRROR = S.Section("glass"), S.Section("mirror")


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def gen_half_vector(wi, wo, eta_i, eta_o):
    """Walter's generalised half vector for directions pointing away from the vertex, with the
    indices on the side of wi and of wo: parallel to the normal at a specular event."""
    return unit(eta_i * np.asarray(wi) + eta_o * np.asarray(wo))


def sides(sc, v, prev, nxt):
    """Indices of the media of the incoming and outgoing segments at a sphere vertex."""
    n = v.normal
    eta_in = sc.eta if np.dot(prev - v.pos, n) < 0 else 1.0
    eta_out = sc.eta if np.dot(nxt - v.pos, n) < 0 else 1.0
    return eta_in, eta_out


def assert_specular(sc, verts):
    """Every sphere vertex of the path obeys reflection / refraction (independent half-vector test)."""
    for i in range(1, len(verts) - 1):
        v = verts[i]
        if v.surface != S.SPHERE:
            continue
        wi, wo = unit(verts[i - 1].pos - v.pos), unit(verts[i + 1].pos - v.pos)
        ei, eo = sides(sc, v, verts[i - 1].pos, verts[i + 1].pos) if sc.sphere == "glass" else (1.0, 1.0)
        h = gen_half_vector(wi, wo, ei, eo) if ei == eo else unit(ei * wi + eo * wo)
        # |h x n| = 0 up to round-off of the traced directions (1e-9: a few ulps of O(1) geometry)
        assert np.linalg.norm(np.cross(h, v.normal)) < 1e-9, (i, h, v.normal)


def test_cast_by_hand():
    cam = np.array(GLASS.camera)
    t, s = S.cast(GLASS, cam, np.array([0.0, 0.0, -1.0]))
    assert s == S.FLOOR and t == pytest.approx(cam[2], rel=1e-12)
    t, s = S.cast(GLASS, np.array([0.6, 0.0, 2.0]), np.array([0.0, 0.0, -1.0]))     # onto the sphere top
    assert s == S.SPHERE and t == pytest.approx(2.0 - 1.6, rel=1e-12)
    t, s = S.cast(GLASS, np.array([0.6, 0.0, 2.0]), np.array([0.0, 0.0, 1.0]))      # up into the light
    assert s == S.LIGHT and t == pytest.approx(1.0, rel=1e-12)
    assert S.cast(GLASS, cam, np.array([-1.0, 0.0, 0.0]))[1] == -1                   # out of the open side


def test_film_of_inverts_camera_direction():
    for film in (0.3, 17.0, 40.5, 63.9):
        p = np.array(GLASS.camera) + 2.0 * S.camera_direction(GLASS, film)
        assert S.film_of(GLASS, p) == pytest.approx(film, abs=1e-9)


def test_base_paths_obey_specular_laws():
    for sc in (GLASS, MIRROR):
        for film in np.linspace(1, 63, 25):
            assert_specular(sc, S.trace_base(sc, film, [0.3, 0.7, 0.5]))
    base = S.caustic_example(GLASS, 0.5)
    assert base is not None and base[-1].surface == S.LIGHT and base[1].surface == S.FLOOR
    assert_specular(GLASS, base)


def test_reconnection_shares_the_rest_of_the_path():
    base = S.trace_base(GLASS, 38, [0.95, 0.3, 0.6])
    res = S.shift_path(GLASS, base, 2.0, "replay+reconnection")
    assert res.ok and res.actions == ["reconnection"]
    assert all(a is b for a, b in zip(res.offset[2:], base[2:])) and len(res.offset) == len(base)
    # the offset's first vertex is where the camera ray through film + 2 hits the floor (by hand)
    d = S.camera_direction(GLASS, S.film_of(GLASS, base[1].pos) + 2.0)
    cam = np.array(GLASS.camera)
    assert np.allclose(res.offset[1].pos, cam - cam[2] / d[2] * d, atol=1e-12)


def test_halfvector_copy_keeps_specular_vertices_specular():
    """Through glass and off the mirror, the offset's sphere vertices obey the specular laws too
    (the half vector copied at a smooth vertex is the normal)."""
    for sc, film in ((GLASS, 14), (MIRROR, 30)):
        base = S.trace_base(sc, film, [0.05, 0.3, 0.6], max_vertices=5)
        res = S.shift_path(sc, base, 1.0, "halfvector+reconnection")
        assert res.ok, res.reason
        assert "halfvector" in res.actions
        assert_specular(sc, res.offset)


def test_manifold_offset_is_a_caustic_path_to_the_same_light_point():
    base = S.caustic_example(GLASS, 1.0)
    res = S.shift_path(GLASS, base, 1.0, "halfvector+reconnection+manifold")
    assert res.ok and res.actions == ["manifold"]
    assert res.offset[-1] is base[-1]
    assert_specular(GLASS, res.offset)
    assert not np.allclose(res.offset[2].pos, base[2].pos, atol=1e-6)    # the chain did move


@pytest.mark.parametrize("policy", ["replay", "replay+reconnection", "halfvector+reconnection",
                                    "halfvector+reconnection+manifold"])
def test_zero_shift_never_fails_and_rates_are_fractions(policy):
    films = np.arange(0.5, 64, 8.0)
    rates, counts, reasons = S.failure_rates(GLASS, policy, films, (0.0, 2.0), 3, 2)
    assert rates.shape == (2, len(films))
    assert np.all(rates[0] == 0.0), "an offset identical to its base path must never fail"
    assert np.all((rates >= 0) & (rates <= 1 + 1e-12))
    assert sum(c[0] for c in counts.values()) > 0
    assert sum(reasons.values()) == round(rates[1].sum() * 3)      # every failure has its reason


def test_jacobian_table_agrees_and_has_power():
    rows = C.jacobian_table(3, 5)
    kinds = {(r["shift"], r["case"]) for r in rows}
    assert len(kinds) == len(C.CASES)
    # 1e-6 relative: the finite differences are accurate to ~1e-9 (module docstring)
    assert max(r["rel_err"] for r in rows) < 1e-6
    assert sum(abs(r["analytic"] - 1) > 1e-3 for r in rows) > len(rows) / 2   # J = 1 would fail
    assert "max rel err" in C.summary(rows)


def test_bad_section_is_refused():
    with pytest.raises(ValueError, match="glass"):
        S.Section("wood")
    with pytest.raises(ValueError, match="unknown shift policy"):
        S.shift_path(GLASS, S.trace_base(GLASS, 30, [0.5]), 1.0, "teleport")
