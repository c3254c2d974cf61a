"""Named tolerances: the small numbers that guard a division, a comparison of floats or a
rounding, each named for what it guards.

A module imports the one it needs (``from meshmocap._tolerances import NORM_FLOOR``). The
values are those the code used as bare literals before they were named here, so naming
them changed no result. Tolerances that belong to one algorithm's definition (the damping
of :mod:`meshmocap.geometry.levenberg_marquardt`, a tracker's stopping rule) stay named in
their own module.
"""

__all__ = [
    "ANTIPARALLEL",
    "DEPTH_FLOOR",
    "DIVISOR_FLOOR",
    "NORM_FLOOR",
    "ROUNDING_SLACK",
    "SAME_FPS",
]

#: Smallest norm a vector is divided by (metres, radians or unitless) when it is made a unit
#: vector or scaled to a length: a shorter vector stays near zero instead of blowing up.
NORM_FLOOR = 1e-12

#: Smallest denominator of a ratio of squared lengths, weights or ``1 + cos`` (same units as
#: the denominator): a guard against 0/0 where the numerator is then 0 too.
DIVISOR_FLOOR = 1e-12

#: Depth (metres along the optical axis) below which a point is taken to lie on the camera
#: plane: projecting divides by this instead of by zero.
DEPTH_FLOOR = 1e-12

#: Two frame rates (Hz) closer than this are the same rate.
SAME_FPS = 1e-9

#: Slack added before ``floor`` (subtracted before ``ceil``) of a ratio meant to be a whole
#: number (grid cells, frame counts, points kept): 3.0 computed as 2.9999999999 still counts
#: 3.
ROUNDING_SLACK = 1e-9

#: Cosine within this of −1: two unit vectors are antiparallel, and the rotation taking one
#: to the other has no unique axis.
ANTIPARALLEL = 1e-9
