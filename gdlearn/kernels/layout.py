"""Row layouts of the compiled scene arrays shared by every numba kernel.

The compiled scene (:mod:`gdlearn.scene.compile`) is a tuple of contiguous float64/int32 arrays
(structure of arrays). Materials and media are rows of fixed width; these constants name the
columns so a kernel reads ``mat[MAT_ALPHA]`` instead of a magic number. Numba freezes module-level
integers at compile time, so using them costs nothing.
"""

# --- BSDF types (column MAT_TYPE) ---------------------------------------------------------------
DIFFUSE = 0
CONDUCTOR = 1
ROUGHCONDUCTOR = 2
DIELECTRIC = 3
ROUGHDIELECTRIC = 4
PLASTIC = 5
ROUGHPLASTIC = 6
NULL = 7

BSDF_TYPES = {"diffuse": DIFFUSE, "conductor": CONDUCTOR, "roughconductor": ROUGHCONDUCTOR,
              "dielectric": DIELECTRIC, "roughdielectric": ROUGHDIELECTRIC, "plastic": PLASTIC,
              "roughplastic": ROUGHPLASTIC, "null": NULL}

# --- microfacet distributions (column MAT_DIST) -------------------------------------------------
BECKMANN = 0
GGX = 1

# --- material row: one row of float64 per BSDF --------------------------------------------------
MAT_TYPE = 0          # one of the BSDF types above
MAT_TWOSIDED = 1      # 1.0 if wrapped in <bsdf type="twosided">
MAT_R = 2             # 3 columns: reflectance / diffuse_reflectance / conductor specular_reflectance
MAT_SR = 5            # 3 columns: specular_reflectance of dielectrics and plastics
MAT_ST = 8            # 3 columns: specular_transmittance of dielectrics
MAT_ALPHA = 11        # microfacet roughness alpha
MAT_DIST = 12         # BECKMANN or GGX
MAT_ETA = 13          # int_ior / ext_ior
MAT_NONLINEAR = 14    # plastic's nonlinear flag
MAT_AUX = 15          # 5 columns a BSDF may fill at compile time (e.g. plastic's internal Fresnel)
MAT_WIDTH = 20

# --- medium row ---------------------------------------------------------------------------------
MED_SIGMA_T = 0       # 3 columns, extinction per unit length (scale applied)
MED_ALBEDO = 3        # 3 columns, single-scattering albedo sigma_s / sigma_t
MED_G = 6             # Henyey-Greenstein g (0 for isotropic)
MED_WIDTH = 8

# --- vertex classes: what kind of scattering happened at a path vertex ---------------------------
# Used by the effects classification (kernels/pathclass.py) and by the shift mappings, which decide
# between reconnection, half-vector copy and manifold exploration from these.
V_DIFFUSE = 0         # a diffuse BSDF
V_GLOSSY = 1          # a microfacet BSDF with alpha >= the roughness threshold (connectable)
V_SPECULAR = 2        # a delta lobe, or a microfacet BSDF with alpha < the threshold
V_MEDIUM = 3          # a scattering event in a participating medium

#: default roughness threshold below which a vertex counts as (near-)specular.
ROUGHNESS_THRESHOLD = 0.05
