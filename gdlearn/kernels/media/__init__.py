"""Homogeneous media: transmittance, free-flight sampling and phase functions."""
