"""Which BSDF families a kernel is compiled with: the material table's *tier*.

numba compiles a kernel once per type of its arguments, and it types an array's write flag and
memory order. :func:`gdlearn.scene.compile.compile_scene` hands the kernels the material table in
one of four forms (:func:`tiered_table`), chosen by the families the scene has, and every kernel
that reads ``sa.materials`` is compiled per form:

======  ================================================  ================================
tier    BSDF families                                     the table numba is given
======  ================================================  ================================
lean    diffuse, null (:data:`LEAN_TYPES`)                read-only, row-major
smooth  + conductor, dielectric (:data:`SMOOTH_TYPES`)    read-only, column-major
glossy  lean + rough conductor, rough plastic             writable, column-major
        (:data:`GLOSSY_TYPES`)
all     every family                                      writable, row-major (a row made by
                                                          ``dispatch.material_row``, a user's table)
======  ================================================  ================================

:mod:`gdlearn.kernels.bsdf.dispatch` reads the tier from a row's type (:func:`tier_of`) and types
``bsdf_sample``, ``bsdf_eval`` and ``bsdf_pdf`` with that tier's families only. The plastics and
the rough families, inlined into every caller, were a quarter of ``pt``'s cold compile on the fog
box, and more than a third of gpt's on the glass sphere close-up (benchmarks/README.md, "Only the
families a scene has"); the glossy tier took 3 s off pt's and 5-11 s off gpt's on the glossy box
("A glossy tier"). A row's type carries two bits (write flag, row-major or strided), so four tiers
is as far as this goes. A column-major table of one row is row-major too (numpy sets both flags),
so a one-material scene outside the lean tier gets every family. The rule is checked against each
shipped scene file, and the tiers' images against the full kernels', in tests/test_bsdf_lean.py.
"""
import numpy as np

from gdlearn.kernels import layout as L

#: the BSDF types of a lean material table (read-only, row-major)
LEAN_TYPES = (L.DIFFUSE, L.NULL)
#: the BSDF types of a smooth one (read-only, column-major): the lean ones and the delta-only families
SMOOTH_TYPES = LEAN_TYPES + (L.CONDUCTOR, L.DIELECTRIC)
#: the BSDF types of a glossy one (writable, column-major): the lean ones and the rough reflectors
GLOSSY_TYPES = LEAN_TYPES + (L.ROUGHCONDUCTOR, L.ROUGHPLASTIC)


def table_tier(materials: np.ndarray) -> str:
    """"lean", "smooth", "glossy" or "all": the first tier whose families hold every row of
    ``materials``. A column-major table of one row is row-major too, so only "lean" and "all" can
    name a one-row table."""
    types = materials[:, L.MAT_TYPE].astype(np.int64)
    if np.isin(types, LEAN_TYPES).all():
        return "lean"
    if materials.shape[0] > 1:
        if np.isin(types, SMOOTH_TYPES).all():
            return "smooth"
        if np.isin(types, GLOSSY_TYPES).all():
            return "glossy"
    return "all"


#: each tier's table form, (writable, memory order): the one place the encoding is written down.
#: numba types a row of a column-major table as strided (layout "A"), of a row-major one as "C".
FORMS = {"lean": (False, "C"), "smooth": (False, "F"), "glossy": (True, "F"), "all": (True, "C")}
_TIER_OF_ROW = {(writable, "C" if order == "C" else "A"): tier for tier, (writable, order) in FORMS.items()}


def tiered_table(materials: np.ndarray) -> np.ndarray:
    """A copy of ``materials`` in the form of its tier (:func:`table_tier`, :data:`FORMS`): the
    kernels compiled for it leave the other BSDF families out."""
    writable, order = FORMS[table_tier(materials)]
    table = np.array(materials, dtype=np.float64, order=order)
    table.flags.writeable = writable
    return table


def tier_of(mat) -> str:
    """At typing: the tier of the table that ``mat`` (a numba array type) is a row of
    (:data:`FORMS` read backwards from the row's write flag and layout)."""
    layout = getattr(mat, "layout", "C")
    return _TIER_OF_ROW[(getattr(mat, "mutable", True), "C" if layout == "C" else "A")]
