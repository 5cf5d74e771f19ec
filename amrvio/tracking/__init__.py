"""Feature tracking shared by the VO front-end, the diagnostics and the photometric calibration.

Layer: above ``geometry``, below ``photometric`` (imports ``errors``, ``types`` and ``geometry``
only).

- :mod:`~amrvio.tracking.brightness`: brightness invariance (``affine | normalise | none``): the
  quantile affine model and the contrast normalisation;
- :mod:`~amrvio.tracking.detect`: Shi-Tomasi corners with a mask, grid bucketing and exclusion of
  existing points;
- :mod:`~amrvio.tracking.lk`: pyramidal Lucas-Kanade with optional forward-backward and epipolar
  checks and predicted positions as the initial guess.
"""
