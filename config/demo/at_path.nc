%
(A 20 mm square with a half-circle side, written by hand for the at_controller rostest)
(rapid to the corner, feed moves at 1200 mm/min, coolant on, ends at X5 Y5 Z-1)
O0007
G21 G90 G17
G00 X5. Y5. Z2.
M08
S12000 M03
G01 Z-1. F600
G01 X25. F1200
Y25.
G02 X5. Y25. I-10. J0.
G01 Y5.
M09
M05
M30
%
