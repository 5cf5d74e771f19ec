"""Photometric models (seed sections 4 and 6.2).

- :mod:`~amrvio.photometric.affine`: affine brightness fit ``I2 = a I1 + b`` (closed form, robust);
- :mod:`~amrvio.photometric.gain`: the same fit made proof against clipping and symmetric in the
  two frames (the diagnostics' exposure change);
- :mod:`~amrvio.photometric.model`: ``I = G(t V(x) L)``: response, radial vignette, and the DSO-style
  :class:`~amrvio.photometric.model.PhotometricCalibration` (pcalib.txt + vignette.png) applied to images;
- :mod:`~amrvio.photometric.calibrate`: estimation of G, V and exposures from tracked points.
"""
