"""Independent references for gdlearn's estimators.

* :mod:`gdlearn.crosscheck.mitsuba`: render a scene file with Mitsuba 3 (``render_mitsuba``), mean and
  per-pixel standard error over independent seeds (``mitsuba_mean_stderr``), and a safe probe of
  which Mitsuba variants work on this machine (``variant_works``).
* :mod:`gdlearn.crosscheck.compare`: the noise-calibrated comparison of two Monte Carlo images (block
  z-scores with both estimates' standard errors, Bonferroni bound, relative bias of the image mean).
* :mod:`gdlearn.crosscheck.store`: the cached reference files in ``tests/references/`` (scene hash,
  settings, staleness check) and the list of reference cases.
* :mod:`gdlearn.crosscheck.fuzz`: random scenes of the documented subset rendered by both renderers and
  compared block by block; a failure is shrunk to a minimal scene (``python -m gdlearn.crosscheck fuzz``).

Importing this package does not import Mitsuba; only the functions that render do.
"""
