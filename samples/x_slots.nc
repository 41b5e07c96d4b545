%
(x_slots.nc: slots along X, cut in both directions, for an X-only calibration)
(machine coordinates, no work offset or tool length needed)
N10 G21 G90 G17 G94
N20 G0 Z50.0
N30 G0 X20.0 Y40.0
N40 G1 Z30.0 F300
N50 G1 X280.0 F1200
N60 G1 Y60.0
N70 G1 X20.0
N80 G1 Y80.0
N90 G1 X150.0
N100 G1 X90.0
N110 G0 Z50.0
N120 M30
%
