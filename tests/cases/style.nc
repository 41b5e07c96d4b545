n1 g21 g90 g17   (lower case, odd spacing, comments)
/n2 g0 x50 y50 z100 ; block delete: executed as the switch is off
n3 g0 X 60.5   Y 70.25
n4 G1Z90F200(plunge)
n5 G01 X+80 y70.25
n6 x100.0	;tab before comment
n7 G0 Z100
%
n8 G0 X-0 Y80 (minus zero in the input)