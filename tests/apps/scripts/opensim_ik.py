"""Inverse kinematics of a meshmocap marker export (.trc or .c3d) in OpenSim.

Runs with OpenSim's Python package (``pip install -e ".[opensim]"``, OpenSim 4.6)::

    meshmocap export walk-patch --out walk.trc
    python opensim_ik.py walk.trc --out walk_ik.mot --model walk.osim

The export holds the 15 evaluation joints as markers (``pelvis``, ``thorax``,
``left_hip`` ... ``right_ankle``). The script reads them with OpenSim's file adapters
(``TRCFileAdapter``; a C3D with ``C3DFileAdapter`` where the OpenSim build has it, else with
ezc3d, the library that adapter is built on, turning the C3D's Z-up lab frame into
OpenSim's Y up), builds a lower-body model whose virtual markers sit at those joints,
its segments as long as the marker data's mean pelvis width, thigh and shank, and runs
OpenSim's inverse kinematics solver frame by frame:

* ``pelvis``: a free joint (3 rotations, 3 translations) carrying the ``pelvis``,
  ``thorax``, ``left_hip`` and ``right_hip`` markers; its Y axis runs up the trunk line
  (pelvis to thorax), Z to the right hip, X forward;
* ``hip_l``, ``hip_r``: flexion (about the pelvis's Z), adduction, rotation; the femur
  carries the knee marker;
* ``knee_l``, ``knee_r``: flexion only (about the femur's Z, positive when the shank swings
  back); the tibia carries the ankle marker.

It writes the coordinates as a .mot file (degrees; load it on the saved .osim model in the
OpenSim GUI) and prints the root-mean-square marker error.
"""

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import opensim as osim

SIDES = {"l": "left", "r": "right"}
#: Z-up lab frame (meshmocap's, a C3D's) to OpenSim's: X = -y, Y = z, Z = -x.
Z_UP_TO_OPENSIM = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])


def read_markers(path: Path) -> osim.TimeSeriesTableVec3:
    """The markers of a .trc or .c3d file in OpenSim's frame (Y up), metres."""
    if path.suffix.lower() == ".trc":
        table = osim.TimeSeriesTableVec3(str(path))  # OpenSim's TRCFileAdapter
        scale = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}[table.getTableMetaDataAsString("Units")]
        return table_from_array(table_array(table) * scale, table)
    if hasattr(osim, "C3DFileAdapter"):
        tables = osim.C3DFileAdapter().read(str(path))
        table = osim.C3DFileAdapter.getMarkersTable(tables)
        scale = {"mm": 1e-3, "m": 1.0}[table.getTableMetaDataAsString("Units")]
        return table_from_array(table_array(table) @ Z_UP_TO_OPENSIM.T * scale, table)
    import ezc3d  # this OpenSim build has no C3D adapter: read it as the adapter does

    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    scale = {"mm": 1e-3, "m": 1.0}[point["UNITS"]["value"][0]]
    xyz = c3d["data"]["points"][:3].transpose(2, 1, 0) * scale  # (frames, markers, 3)
    rate = float(point["RATE"]["value"][0])
    first = c3d["header"]["points"]["first_frame"]
    times = (first + np.arange(len(xyz))) / rate
    return table_from_array(xyz @ Z_UP_TO_OPENSIM.T, None, times, point["LABELS"]["value"])


def table_array(table: osim.TimeSeriesTableVec3) -> np.ndarray:
    """(frames, markers, 3) float64 of ``table``; gaps are NaN."""
    flat = table.flatten()  # (frames, 3 x markers) doubles; keep it alive while read
    matrix = flat.getMatrix()
    return matrix.to_numpy().reshape(table.getNumRows(), table.getNumColumns(), 3)


def table_from_array(xyz, like=None, times=None, labels=None) -> osim.TimeSeriesTableVec3:
    """A marker table of ``xyz`` (frames, markers, 3), metres, with the times and labels of
    ``like`` unless given."""
    times = list(like.getIndependentColumn()) if times is None else list(times)
    labels = list(like.getColumnLabels()) if labels is None else list(labels)
    table = osim.TimeSeriesTableVec3()
    table.setColumnLabels(labels)
    for t, row in zip(times, xyz, strict=True):
        table.appendRow(float(t), osim.RowVectorVec3([osim.Vec3(*map(float, p)) for p in row]))
    table.addTableMetaDataString("Units", "m")
    return table


def segments(xyz: np.ndarray, labels: list[str]) -> dict:
    """Mean segment geometry of the marker data (metres): the hips and the thorax in the
    pelvis's frame, thigh and shank lengths."""
    at = {name: xyz[:, labels.index(name)] for name in labels}
    up = at["thorax"] - at["pelvis"]
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    right = at["right_hip"] - at["left_hip"]
    right -= np.sum(right * up, axis=1, keepdims=True) * up
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    frame = np.stack([np.cross(up, right), up, right], axis=1)  # rows: X, Y, Z

    def local(name):
        return np.einsum("fij,fj->fi", frame, at[name] - at["pelvis"]).mean(axis=0)

    def length(a, b):
        return float(np.linalg.norm(at[a] - at[b], axis=1).mean())

    geometry = {"thorax": local("thorax")}
    for s, side in SIDES.items():
        geometry[f"hip_{s}"] = local(f"{side}_hip")
        geometry[f"thigh_{s}"] = length(f"{side}_hip", f"{side}_knee")
        geometry[f"shank_{s}"] = length(f"{side}_knee", f"{side}_ankle")
    return geometry


def rotation_axes(names_axes: list[tuple[str, tuple]]) -> osim.SpatialTransform:
    """A joint's spatial transform: rotations about the given axes, each driven by its
    coordinate (an axis with no name stays fixed), no translation."""
    st = osim.SpatialTransform()
    for k, (name, axis) in enumerate(names_axes):
        ax = st.updTransformAxis(k)
        ax.setAxis(osim.Vec3(*axis))
        if name:
            ax.setCoordinateNames(osim.ArrayStr(name, 1))
            ax.set_function(osim.LinearFunction())  # a copy: setFunction would adopt it
        else:
            ax.set_function(osim.Constant(0.0))
    return st


def lower_body_model(geometry: dict) -> osim.Model:
    """A pelvis, femurs and tibias with the markers at the joints (see the docstring)."""
    model = osim.Model()
    model.setName("meshmocap_lower_body")
    inertia = osim.Inertia(0.1, 0.1, 0.1)
    pelvis = osim.Body("pelvis", 10.0, osim.Vec3(0), inertia)
    model.addBody(pelvis)
    free = osim.FreeJoint("ground_pelvis", model.getGround(), pelvis)
    for k, name in enumerate(["rx", "ry", "rz", "tx", "ty", "tz"]):
        free.upd_coordinates(k).setName(f"pelvis_{name}")
    model.addJoint(free)
    model.addMarker(osim.Marker("pelvis", pelvis, osim.Vec3(0)))
    model.addMarker(osim.Marker("thorax", pelvis, osim.Vec3(*geometry["thorax"])))
    for s, side in SIDES.items():
        femur = osim.Body(f"femur_{s}", 8.0, osim.Vec3(0), inertia)
        tibia = osim.Body(f"tibia_{s}", 4.0, osim.Vec3(0), inertia)
        model.addBody(femur)
        model.addBody(tibia)
        hip = rotation_axes(
            [
                (f"hip_flexion_{s}", (0, 0, 1)),
                (f"hip_adduction_{s}", (1 if s == "r" else -1, 0, 0)),
                (f"hip_rotation_{s}", (0, 1 if s == "r" else -1, 0)),
            ]
        )
        hip_at = osim.Vec3(*geometry[f"hip_{s}"])
        model.addJoint(
            osim.CustomJoint(
                f"hip_{s}", pelvis, hip_at, osim.Vec3(0), femur, osim.Vec3(0), osim.Vec3(0), hip
            )
        )
        knee = rotation_axes([(f"knee_flexion_{s}", (0, 0, -1)), ("", (1, 0, 0)), ("", (0, 1, 0))])
        knee_at = osim.Vec3(0, -geometry[f"thigh_{s}"], 0)
        model.addJoint(
            osim.CustomJoint(
                f"knee_{s}", femur, knee_at, osim.Vec3(0), tibia, osim.Vec3(0), osim.Vec3(0), knee
            )
        )
        model.addMarker(osim.Marker(f"{side}_hip", pelvis, hip_at))
        model.addMarker(osim.Marker(f"{side}_knee", femur, knee_at))
        model.addMarker(
            osim.Marker(f"{side}_ankle", tibia, osim.Vec3(0, -geometry[f"shank_{s}"], 0))
        )
    model.finalizeConnections()
    return model


def inverse_kinematics(model: osim.Model, markers: osim.TimeSeriesTableVec3):
    """Coordinates (frames, coordinates; degrees for rotations, metres for translations),
    their names, and the RMS marker error per frame (metres)."""
    names = [m.getName() for m in model.getMarkerSet()]
    weights = osim.SetMarkerWeights()
    for name in names:
        weights.cloneAndAppend(osim.MarkerWeight(name, 1.0))
    used = osim.TimeSeriesTableVec3(markers)
    for label in list(used.getColumnLabels()):
        if label not in names:
            used.removeColumn(label)
    reference = osim.MarkersReference(used, weights)
    state = model.initSystem()
    solver = osim.InverseKinematicsSolver(model, reference, osim.SimTKArrayCoordinateReference())
    solver.setAccuracy(1e-6)
    coordinates = list(model.getCoordinateSet())
    times = list(used.getIndependentColumn())
    values, errors = [], []
    state.setTime(times[0])
    solver.assemble(state)
    for t in times:
        state.setTime(t)
        solver.track(state)
        values.append([c.getValue(state) for c in coordinates])
        squared = osim.SimTKArrayDouble()
        solver.computeCurrentSquaredMarkerErrors(squared)
        errors.append(math.sqrt(sum(squared.getElt(k) for k in range(squared.size())) / len(names)))
    values = np.array(values)
    rotational = [c.getMotionType() == osim.Coordinate.Rotational for c in coordinates]
    values[:, rotational] = np.degrees(values[:, rotational])
    return values, [c.getName() for c in coordinates], np.array(errors), np.array(times)


def write_mot(path: Path, times, values, names) -> None:
    """The coordinates as an OpenSim motion file (degrees)."""
    table = osim.TimeSeriesTable()
    table.setColumnLabels(names)
    for t, row in zip(times, values, strict=True):
        table.appendRow(float(t), osim.RowVector([float(v) for v in row]))
    table.addTableMetaDataString("inDegrees", "yes")
    osim.STOFileAdapter().write(table, str(path))


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("markers", type=Path, help="a meshmocap export: .trc or .c3d")
    parser.add_argument("--out", type=Path, required=True, help="coordinates (.mot)")
    parser.add_argument("--model", type=Path, help="also save the model (.osim)")
    args = parser.parse_args(argv)

    markers = read_markers(args.markers)
    labels = list(markers.getColumnLabels())
    model = lower_body_model(segments(table_array(markers), labels))
    values, names, errors, times = inverse_kinematics(model, markers)
    write_mot(args.out, times, values, names)
    if args.model:
        model.printToXML(str(args.model))
    print(
        f"{args.markers.name}: {len(times)} frames, {len(labels)} markers; inverse kinematics "
        f"on {model.getName()} ({len(names)} coordinates): RMS marker error "
        f"{1000 * errors.mean():.1f} mm (max {1000 * errors.max():.1f} mm); wrote {args.out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
