"""The camera distance copy (Gruson et al. 2018, §4.1, Eq. 14-15): the offset path scatters in the
medium at the *same distance* from its previous vertex as the base path, along its own ray.

Base and offset leave their vertices along directions d and d' (the pixel shift moved the camera
ray, or an earlier shift moved the vertex); the base's free flight ended at distance t. The offset
vertex is x' = o' + t d'. In the (direction, distance) parametrisation of a medium vertex,
dV = t^2 dw dt on both paths, so with the direction's own Jacobian accounted for where it is
shifted the distance part of the Jacobian is dt'/dt = 1 (:data:`JACOBIAN`). Gruson et al. prefer
this copy to shifts that keep the vertex's *position* (reconnection to the base's medium vertex) or
its optical depth: those move gather points far where the two rays diverge or the medium is dense.

The shift fails when the offset's ray cannot reach t inside a medium: it meets a non-null surface
or leaves the scene first, or the point at t lies in vacuum (vertex kinds must match, STAR §3.5).
The rule is symmetric in base and offset, so the backward shift fails on the same pairs.

:func:`lands_on_segment` is the map applied to one sub-segment of the offset's ray between null
interfaces; ``integrators.path.gpt_volume.flight.offset_flight`` walks the segments with it.
"""
from gdlearn.kernels.jit import leaf

#: dt'/dt of the distance copy: the offset keeps the base's distance
JACOBIAN = 1.0


@leaf
def lands_on_segment(tau, travelled, t_segment):
    """Does the copied distance ``tau`` fall on the sub-segment that starts at distance ``travelled``
    along the offset's ray and is ``t_segment`` long? Returns ``(lands, t_local)``: the distance
    within the sub-segment (clamped at 0 for a segment that starts just past tau by rounding)."""
    if travelled + t_segment > tau:
        return True, max(tau - travelled, 0.0)
    return False, 0.0
