%
(The demo's path for the '@' controller: a 150 mm square with a half-circle side)
(rapid to the corner, feed moves at 3000 mm/min, coolant on, ends at X10 Y10 Z-1)
O0007
G21 G90 G17
G00 X10. Y10. Z2.
M08
S12000 M03
G01 Z-1. F600
G01 X160. F3000
Y160.
G02 X10. Y160. I-75. J0.
G01 Y10.
M09
M05
M30
%
