%
(qCNC phrasing: G90 and G01 are implied, coordinates in mm)
N10 X0 Y0 Z5
N20 X10 Y0 Z5
N30 Z-1
N40 X10 Y10
N50 X0 Y10
N60 X0 Y0
N70 Z5
N80 M30
%
