%
O0002(FACE AND CONTOUR)
(Written for robstiff in the form a generic Fanuc post of Mastercam writes)
(the same job as face_contour_fanuc.nc: the same moves, with Mastercam's)
(tool comment, safety block and returns.)
(MATERIAL - ALUMINUM MM - 6061)
(TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - 75.)
N100 G21
N102 G0 G17 G40 G49 G80 G90
N104 T1 M6
N106 G0 G90 G54 X-60. Y-40. S3600 M3
N108 G43 H1 Z15. M8
N110 Z5.
N112 G1 Z-2. F300.
N114 X60. F1200.
N116 G3 X60. Y0. I0. J20.
N118 G1 X-40.
N120 G2 X-60. Y20. I0. J20.
N122 G1 Y100.
N124 G0 Z15.
N126 M5
N128 G91 G28 Z0. M9
N130 G28 X0. Y0.
N132 M30
%
