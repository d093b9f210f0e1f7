%
O1001 (FACE AND CONTOUR)
(Written for robstiff in the form a generic Fanuc post of Fusion 360 /)
(HSMWorks writes: a 120 x 80 mm aluminium plate, program zero on its top)
(at its centre; a 75 mm face mill plunges 2 mm at the plate's corner,)
(faces along X, turns back on an R20 half circle, contours back along Y0)
(and leaves on an R20 quarter arc.)
(T1 D=75. CR=0. - ZMIN=-2. - FACE MILL)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90

(FACE AND CONTOUR)
N30 T1 M6
N35 S3600 M3
N40 G54
N45 M8
N50 G0 X-60. Y-40.
N55 G43 Z15. H1
N60 G0 Z5.
N65 G1 Z-2. F300.
N70 X60. F1200.
N75 G3 X60. Y0. R20.
N80 G1 X-40.
N85 G2 X-60. Y20. R20.
N90 G1 Y100.
N95 G0 Z15.
N100 M9
N105 M5
N110 G28 G91 Z0.
N115 G90
N120 M30
%
