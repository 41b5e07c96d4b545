(bore the 20H7 hole of s500_bore.operation.json: X Y Z are the spindle gauge point, the tool reaches 100 mm below it)
G21 G90
G0 X200 Y250 Z200
G1 Z180 F60
G1 Z200
M30
