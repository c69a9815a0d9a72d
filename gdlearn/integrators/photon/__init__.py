"""Surface photon-density estimators: SPPM and memoryless progressive photon mapping (:mod:`.sppm`),
with their camera pass in :mod:`.gather`; the light side lives in :mod:`gdlearn.photons`."""
