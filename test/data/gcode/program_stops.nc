(The program's own stops for the streaming nodes' rostests: spindle and coolant words, M00, M01,)
(a dwell and M30, and a move after M30 that must never be sent.)
G21 G90 G17
G00 X0 Y0 Z5
S8000 M03
M08
G01 X10 F600
M00 (measure the part)
G01 X20
M01 (optional stop)
G01 X30
G04 P0.3
G01 X40
M05 M09
M30
G01 X99
