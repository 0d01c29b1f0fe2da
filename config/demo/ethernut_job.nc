%
(qCNC phrasing: G90 implied, coordinates in mm; a rapid to the start, then a 150 mm square)
(and its diagonal cut at Z-1, and a rapid up)
N10 G00 X0 Y0 Z5
N20 G01 X150 Y0 Z5
N30 Z-1
N40 X150 Y150
N50 X0 Y150
N60 X0 Y0
N70 X150 Y150
N80 G00 Z5
N90 M30
%
