"""Mirror milling of waffle-grid shells by program correction (Pas & Serkov).

- :mod:`.maps`: measured correction maps ``[B, Z, value]`` added along the spindle axis;
- :mod:`.kdist`: disturbance correction from the back-wall sensor (formulas 1-4);
- :mod:`.feedback`: feedback correction from thickness maps and pocket-to-pocket
  self-tuning in the band ``[T_min, T_max]`` (formulas 7-11);
- :mod:`.deadband`: dead-band ("elastic gap") model of the copying chain;
- :mod:`.synthetic`: a synthetic shell (tilted back wall, drift, thickness pattern).
"""
