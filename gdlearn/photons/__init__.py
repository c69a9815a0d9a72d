"""The light side of the photon estimators.

* :mod:`gdlearn.photons.emit` -- an emitter chosen by power, then a position and a direction with area-measure
  pdfs, for every emitter type of the supported subset;
* :mod:`gdlearn.photons.trace` -- light paths in importance transport (adjoint BSDF, Veach 1997 Sec. 5.2-5.3),
  Russian roulette, traced in parallel into fixed slots and compacted in path order;
* :mod:`gdlearn.photons.records` -- whole light paths as flat structure-of-arrays vertex records (parent, lobe,
  area pdfs, power), from which photons are the stored non-specular vertices;
* :mod:`gdlearn.photons.grid` -- a hashed uniform grid for fixed-radius range queries, rebuilt every pass.

Light path j of pass i draws ``rand(seed, LIGHT_KEY0 + j, i, dim)``: the records are a pure
function of (scene, seed, i, j), the same for any thread count and batch size.
"""
