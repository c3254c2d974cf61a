"""Track a light body, read out the full one.

The cost of every tracker grows with the template's vertices, and a body estimated from a
capture has the bundled topology's 12k of them, far more than the visual hull resolves
(1 cm voxels). So the driver tracks a lighter copy of the template (about
:data:`LIGHT_VERTICES` vertices: the template quadric-decimated, :mod:`meshmocap.geometry.decimate`,
and rigged with the template's own skeleton and blended weights,
:func:`~meshmocap.body.autorig.transfer_rig`) and carries the full surface along:

* **binding** (once, at rest): every full vertex ``x`` is tied to the nearest point ``p``
  of the light surface (its triangle and barycentric coordinates ``b``, normals agreeing)
  and to the offset ``x − p`` expressed in a frame of the light surface at ``p``: the unit
  normal ``n`` interpolated from the vertex normals, the tangent ``t₁`` along the
  triangle's first edge made orthogonal to ``n``, and ``t₂ = n × t₁``;
* **read-out** (every frame): the same point and frame on the deformed light surface give
  ``x' = p' + o₁ t₁' + o₂ t₂' + o₃ n'``. At rest it returns the template exactly; a rigid
  motion of the light surface moves the full one rigidly; vectorised, a few milliseconds
  for 12k vertices.

A track stores the light body's vertices and the binding
(:func:`~meshmocap.io.results.read_track` reads the full surface out), so exports,
per-vertex scores and the player read the full surface, in the template's own topology;
the trackers never see it. Metres, world frame Z up.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from meshmocap._tolerances import NORM_FLOOR
from meshmocap.body.autorig import nearest_surface_points, transfer_rig
from meshmocap.body.template import Template
from meshmocap.errors import InputError, MeshError
from meshmocap.geometry.decimate import decimate_mesh
from meshmocap.geometry.mesh import vertex_normals

__all__ = [
    "LIGHT_VERTICES",
    "SurfaceBinding",
    "TrackingBody",
    "bound_vertices",
    "light_template",
    "surface_binding",
    "tracking_body",
]

#: Vertices of the body the trackers track (a template with at most
#: :data:`LIGHT_MARGIN` times as many is tracked as it is).
LIGHT_VERTICES = 5000
#: A template this much larger than the target at most is not worth lightening.
LIGHT_MARGIN = 1.25


@dataclass(frozen=True, eq=False)
class SurfaceBinding:
    """Full vertices tied to a light surface (module docstring).

    Attributes
    ----------
    F : (m, 3) int64, the light surface's triangles
    tri : (n,) int64, the light triangle of each full vertex
    bary : (n, 3) float64, barycentric coordinates of its nearest point in that triangle
    offset : (n, 3) float64, metres: the offset in the frame (t₁, t₂, n) there
    """

    F: np.ndarray
    tri: np.ndarray
    bary: np.ndarray
    offset: np.ndarray


def _surface_frames(
    V: np.ndarray, F: np.ndarray, tri: np.ndarray, bary: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Points ``p`` (n, 3) and frames (n, 3, 3) (rows t₁, t₂, n) of the surface ``(V, F)``
    at the barycentric points ``(tri, bary)``."""
    N = vertex_normals(V, F)
    T = F[tri]
    p = np.einsum("nk,nkc->nc", bary, V[T])
    n = np.einsum("nk,nkc->nc", bary, N[T])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), NORM_FLOOR)
    e = V[T[:, 1]] - V[T[:, 0]]
    t1 = e - np.einsum("nc,nc->n", e, n)[:, None] * n
    t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), NORM_FLOOR)
    return p, np.stack([t1, np.cross(n, t1), n], axis=1)


def surface_binding(
    V: np.ndarray, F: np.ndarray, V_light: np.ndarray, F_light: np.ndarray
) -> SurfaceBinding:
    """Bind the full surface ``(V (n, 3), F)`` to the light surface ``(V_light, F_light)``
    (both metres, in the same place: e.g. a template and its decimated copy at rest)."""
    F_light = np.asarray(F_light, dtype=np.int64)
    tri, bary = nearest_surface_points(V, vertex_normals(V, F), V_light, F_light)
    p, frame = _surface_frames(V_light, F_light, tri, bary)
    offset = np.einsum("nab,nb->na", frame, V - p)
    return SurfaceBinding(F_light, tri, bary, offset)


def bound_vertices(binding: SurfaceBinding, V_light: np.ndarray) -> np.ndarray:
    """(n, 3) float64: the full vertices carried by the deformed light vertices
    ``V_light`` (k, 3), metres (module docstring, read-out)."""
    p, frame = _surface_frames(
        np.asarray(V_light, dtype=np.float64), binding.F, binding.tri, binding.bary
    )
    return p + np.einsum("na,nab->nb", binding.offset, frame)


def light_template(template: Template, *, n_vertices: int = LIGHT_VERTICES) -> Template:
    """``template`` decimated to about ``n_vertices`` vertices and rigged with its own
    skeleton, weights (blended), body parts and evaluation joints (module docstring).

    Raises
    ------
    MeshError
        The template's surface cannot be decimated (not a closed 2-manifold).
    """
    Vd, Fd = decimate_mesh(template.V, template.F, n_vertices=int(n_vertices))
    return transfer_rig(template, Vd, Fd, name=f"{template.name}_light{len(Vd)}")


@dataclass(frozen=True, eq=False)
class TrackingBody:
    """The body a tracker tracks and the one read out.

    Attributes
    ----------
    template : Template, the full body (what the track is written in)
    light : Template, the body the tracker tracks (``template`` itself when it is light)
    binding : SurfaceBinding or None (None when ``light`` is ``template``)
    """

    template: Template
    light: Template
    binding: SurfaceBinding | None

    def full_vertices(self, V: np.ndarray) -> np.ndarray:
        """The full body's vertices (n, 3) for the tracked light vertices ``V`` (k, 3)."""
        return V if self.binding is None else bound_vertices(self.binding, V)


#: Light bodies made in this process, by template (the demo's three trackers and a resumed
#: run share one; the same template gives the same light body, decimation is deterministic).
_MADE: dict[tuple[int, int | None], tuple[weakref.ref, TrackingBody]] = {}


def tracking_body(template: Template, *, n_vertices: int | None = LIGHT_VERTICES) -> TrackingBody:
    """The :class:`TrackingBody` of ``template``: tracked on a light copy of about
    ``n_vertices`` vertices when it has more than :data:`LIGHT_MARGIN` times as many (and
    can be decimated), else on itself; ``n_vertices=None`` always tracks the template."""
    key = (id(template), n_vertices)
    ref, body = _MADE.get(key, (None, None))
    if ref is not None and ref() is template:
        return body
    body = TrackingBody(template, template, None)
    if n_vertices is not None:
        if int(n_vertices) < 100:
            raise InputError(f"track: light body vertices must be ≥ 100, found {n_vertices}")
        if template.n_vertices > LIGHT_MARGIN * n_vertices:
            try:
                light = light_template(template, n_vertices=n_vertices)
            except (MeshError, InputError):  # an open or odd surface: track it as it is
                light = None
            if light is not None:
                binding = surface_binding(template.V, template.F, light.V, light.F)
                body = TrackingBody(template, light, binding)
    _MADE[key] = (weakref.ref(template), body)
    return body
