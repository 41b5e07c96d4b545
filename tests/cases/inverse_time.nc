(G93 inverse-time feed: each inserted segment gets its own F)
G21 G90 G17
G0 X100 Y100 Z50
G93 G1 Z40 F60
G2 X120 Y120 I20 J0 F30
G1 X200 Y150 F10
G94 G0 Z60
M2
