(holes_g91.nc: 4 x 3 hole pattern, 25 mm pitch, drilled with incremental moves)
(machine coordinates, no work offset or tool length needed)
G21 G17 G90 G94
G0 Z80.0
G0 X60.0 Y70.0
G91
G1 Z-20.0 F150
G0 Z20.0
G0 X25.0
G1 Z-20.0
G0 Z20.0
G0 X25.0
G1 Z-20.0
G0 Z20.0
G0 X25.0
G1 Z-20.0
G0 Z20.0
G0 Y25.0
G1 Z-20.0
G0 Z20.0
G0 X-25.0
G1 Z-20.0
G0 Z20.0
G0 X-25.0
G1 Z-20.0
G0 Z20.0
G0 X-25.0
G1 Z-20.0
G0 Z20.0
G0 Y25.0
G1 Z-20.0
G0 Z20.0
G0 X25.0
G1 Z-20.0
G0 Z20.0
G0 X25.0
G1 Z-20.0
G0 Z20.0
G0 X25.0
G1 Z-20.0
G0 Z20.0
(a diagonal slot back to the first hole, then a quarter arc)
G1 Z-5.0 F300
G1 X-75.0 Y-50.0 F600
G3 X10.0 Y10.0 I0.0 J10.0
G0 Z5.0
G90
M30
