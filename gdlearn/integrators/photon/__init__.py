"""Surface photon-density estimators: SPPM and memoryless progressive photon mapping (:mod:`gdlearn.integrators.photon.sppm`),
with their camera pass in :mod:`gdlearn.integrators.photon.gather`; the light side lives in :mod:`gdlearn.photons`."""
