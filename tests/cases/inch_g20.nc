G20 G90 G17 (inch program: a 2 x 1.5 inch plate outline with rounded corners)
(machine coordinates in inches, no work offset or tool length needed)
G0 Z3.0
G0 X4.25 Y4.0
M3 S6000
G1 Z2.0 F20.0
G1 X6.0 F30.0
G2 X6.25 Y3.75 I0.0 J-0.25
G1 Y2.75
G2 X6.0 Y2.5 I-0.25 J0.0
G1 X4.25
G2 X4.0 Y2.75 I0.0 J0.25
G1 Y3.75
G2 X4.25 Y4.0 I0.25 J0.0
G21 (switch to mm mid-program)
G1 X120.0 Y90.0 F500
G20
G0 Z3.0
M5
M30
