%
(pocket.nc - finishing pass of a 60 x 40 mm pocket with 8 mm corner radii)
(and a semicircular notch, at working depth: the contour stays in Z = 0)
N10 G21 G17 G90
N20 G0 X-30 Y0            ; rapid to the start, mid left wall (not part of the path)
N30 G1 Y-12 F800          ; down the left wall
N40 G3 X-22 Y-20 I8 J0    ; corner, CCW, I/J centre
N50 G1 X-10
N60 G3 X10 Y-20 R-10      (notch bulging into the pocket wall: 180 deg CCW)
N70 G1 X22 F1200
N80 G3 X30 Y-12 R8        ; corner, R form
N90 G1 Y12
N100 G3 X22 Y20 I-8
N110 G1 X-22
N120 G91 G3 X-8 Y-8 J-8   ; incremental corner
N130 G90 G1 X-30 Y0 F800
N140 G0 X0 Y0             ; retract: dropped (after the last feed move)
N150 M30
%
