(arcs that a strong squareness error turns into lines; modal arc lines keep their G2)
G21 G90 G17 G94
G0 X100 Y100 Z50
G1 Z40 F300
N10 G2 X120 Y120 I20 J0 F600 (quarter, radius 20)
N20 X140 Y100 I0 J-20
N30 G1 X150
N40 G3 X150 Y100.5 R0.25 (tiny arc stays an arc)
N50 G0 Z60
M2
