%
(qCNC seed phrasing: G90 and G01 are implied, coordinates in mm; a 150 mm square and its diagonal)
N10 X0 Y0 Z5
N20 X150 Y0 Z5
N30 Z-1
N40 X150 Y150
N50 X0 Y150
N60 X0 Y0
N70 X150 Y150
N80 Z5
N90 M30
%
