"""Per-frame diagnostics (seed section 1 "compute diagnostics", sections 2-5).

- :mod:`~amrvio.diagnostics.blur`: variance of the Laplacian and the scene-normalised BlurScorer;
- :mod:`~amrvio.diagnostics.smear`: predicted smear field over the exposure (gyro rotation, plus
  translation from the camera's velocity and the depths of tracked points), exposure advice;
- :mod:`~amrvio.diagnostics.tracks`: the diagnostics' own KLT tracks, made to survive exposure
  steps (the reference mapped into the current brightness);
- :mod:`~amrvio.diagnostics.exposure`: exposure change (clip-proof gain/offset, EV) on KLT patches;
- :mod:`~amrvio.diagnostics.parallax`: rotation-compensated parallax against the parallax reference
  frame, and the rule that renews that reference;
- :mod:`~amrvio.diagnostics.excitation`: IMU excitation over a window (degenerate motion);
- :mod:`~amrvio.diagnostics.frame`: the stage ``FrameDiagnostics(config).process(...) -> FrameHealth``;
- :mod:`~amrvio.diagnostics.health`: the ``FrameHealth`` record and its ``health.csv`` rows;
- :mod:`~amrvio.diagnostics.advice`: frame ranges with a cause and a recommendation.
"""
