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
    "BARYCENTRIC_SLACK",
    "DEGENERATE_AXIS",
    "DEPTH_FLOOR",
    "DIVISOR_FLOOR",
    "NEAR_DEPTH",
    "NORM_FLOOR",
    "RELATIVE_DEGENERATE",
    "ROTATION_SLACK",
    "ROUNDING_SLACK",
    "SAME_FPS",
    "SAME_POSITION",
    "SMALL_ANGLE",
    "SMALL_SINE",
    "UNDERFLOW_FLOOR",
    "WINDING_SLACK",
    "ZERO_EXTENT",
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

#: Smallest positive value a length, weight or eigenvalue is clamped to (or added to) before
#: it divides, where only an exact zero needs a guard: any positive float gives a finite
#: quotient, so the result is unchanged wherever the value is not zero.
UNDERFLOW_FLOOR = 1e-300

#: An extent below this is zero (a length in metres, a duration in seconds, a plotted axis's
#: range): a bone with no direction, a box or a range of one value; also the floor such an
#: extent is clamped to before it divides.
ZERO_EXTENT = 1e-9

#: Fraction of a shape's size (raised to the measure's dimension: diameter² for an area,
#: diameter³ for a volume) below which an area or a volume counts as zero: a flat triangle, two
#: cage parts that touch.
RELATIVE_DEGENERATE = 1e-12

#: Depth (metres along a camera's optical axis) a point must exceed to count as in front of
#: the camera; where a projection's derivative divides by the depth, the floor it is clamped
#: to.
NEAR_DEPTH = 1e-6

#: Norm of a cross product of unit vectors below which they are parallel and it gives no axis:
#: another perpendicular is chosen.
DEGENERATE_AXIS = 1e-6

#: Angle (radians) below which a rotation's formulas switch to their Taylor expansions.
SMALL_ANGLE = 1e-6

#: Sine of the angle between two rotations below which spherical interpolation is linear.
SMALL_SINE = 1e-8

#: Largest ``|R Rᵀ − I|`` of a matrix still taken as a rotation (a file's rounding).
ROTATION_SLACK = 1e-6

#: A winding number within this of 1 counts as inside a closed surface.
WINDING_SLACK = 1e-6

#: Two positions (metres) closer than this in every coordinate are the same point.
SAME_POSITION = 1e-6

#: Barycentric coordinates down to minus this count as inside a triangle: a pixel centre on an
#: edge two triangles share is drawn by one of them, not missed by both.
BARYCENTRIC_SLACK = 1e-9
