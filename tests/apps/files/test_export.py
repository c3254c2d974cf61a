"""meshmocap export: each format read back by a library this project did not write (bvhio,
ezc3d, pygltflib, trimesh, the Khronos validator, the csv module; Blender and OpenSim in
test_blender.py and test_opensim.py)."""

import csv
import json
import os
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from meshmocap.apps.files.export import export_track, track_fps, track_rows
from meshmocap.body.markers import marker_vertices
from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS, load_template
from meshmocap.cli import main
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.bvh import read_bvh
from meshmocap.io.gltf import morph_gltf, write_gltf
from meshmocap.io.results import FrameResult, read_track, start_track, write_frame

SCRIPTS = Path(__file__).parents[1] / "scripts"
T = 8


@pytest.fixture(scope="module")
def template():
    return load_template("neutral_5k")


@pytest.fixture(scope="module")
def track_dir(template, tmp_path_factory):
    """A walk on neutral_5k with a smooth non-skinning bulge (≤ 3 mm) on the surface and
    joints 1 mm off the rig's, frames 10..17 of a 60 fps capture; frame 13 failed."""
    root = tmp_path_factory.mktemp("export")
    (root / "cap").mkdir()
    (root / "cap" / "capture.json").write_text(json.dumps({"fps": 60.0}))
    m = procedural_motion("walk", template, duration=T / 60.0, fps=60.0)
    posed = template.pose(m.rotations[:T], m.root_positions[:T])
    rng = np.random.default_rng(0)
    meta = {
        "method": "synthetic",
        "template": "neutral_5k",
        "capture": str(root / "cap"),
        "eval_names": list(EVAL_NAMES),
        "eval_parents": EVAL_PARENTS.tolist(),
    }
    out = root / "track"
    start_track(out, meta, template.F, resume=False)
    for k in range(T):
        V = posed.V[k] + 0.003 * np.sin(8.0 * posed.V[k][:, [2, 0, 1]] + k)
        X = posed.eval_joints[k] + rng.normal(0.0, 0.001, (15, 3))
        bad = k == 3
        flags, msg = (("failed",), "solver diverged") if bad else ((), "")
        write_frame(out, FrameResult(10 + k, X, V, healthy=not bad, flags=flags, message=msg))
    return out


@pytest.fixture(scope="module")
def track(track_dir):
    return read_track(track_dir)


@pytest.fixture(scope="module")
def bvh(track_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("bvh") / "walk.bvh"
    return out, export_track(track_dir, out)


@pytest.fixture(scope="module")
def glb(track_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("glb") / "walk.glb"
    return out, export_track(track_dir, out)


def test_bvh_reskins_to_the_track(bvh, track, template):
    path, res = bvh
    assert res.format == "bvh" and res.n_frames == T and res.fps == 60.0
    assert res.fps_source == "capture.json"
    m = read_bvh(path)
    assert m.skeleton.names == template.skeleton.names and m.fps == 60.0
    posed = template.pose(m.rotations, m.root_positions)
    ok = np.arange(T) != 3  # the failed frame holds frame 2's pose (BVH has no gaps)
    v_err = np.linalg.norm(posed.V[ok] - track.vertices[ok], axis=2).mean()
    j_err = np.linalg.norm(posed.eval_joints[ok] - track.joints[ok], axis=2).mean()
    assert v_err < 0.005 and j_err < 0.005  # the acceptance: 5 mm mean
    assert res.vertex_error_mm == pytest.approx(v_err * 1e3, abs=0.01) and res.gaps == (13,)
    np.testing.assert_allclose(m.rotations[3], m.rotations[2], atol=1e-3)  # 0.06°, refitted


def test_bvh_reads_back_with_bvhio(bvh, track):
    bvhio = pytest.importorskip("bvhio")
    path, _ = bvh
    c = bvhio.readAsBvh(str(path))
    assert c.FrameCount == T and c.FrameTime == pytest.approx(1 / 60.0)
    root = bvhio.readAsHierarchy(str(path))
    root.loadPose(5)
    p = root.filter("LeftFoot")[0].PositionWorld  # Y up, centimetres
    z_up = np.array([p.x, -p.z, p.y]) / 100.0
    assert np.linalg.norm(z_up - track.joints[5, EVAL_NAMES.index("left_ankle")]) < 0.005


def _quat_matrix(q):
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_glb_skins_like_the_spec_says(glb, track, template):
    """Read with pygltflib; skin frame 5 by the glTF rules (node TRS → world matrices,
    inverse bind matrices, JOINTS_0/WEIGHTS_0): the tracked mesh, Y up."""
    import pygltflib

    path, _ = glb
    g = pygltflib.GLTF2.load(str(path))
    blob = g.binary_blob()

    def data(i):
        a = g.accessors[i]
        view = g.bufferViews[a.bufferView]
        dt = {5126: "<f4", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4"}[a.componentType]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
        x = np.frombuffer(blob, dt, a.count * width, view.byteOffset + (a.byteOffset or 0))
        x = x.reshape(a.count, width).astype(np.float64)
        return x / 32767.0 if a.normalized and a.componentType == 5122 else x

    anim = g.animations[0]
    times = data(anim.samplers[0].input).ravel()
    np.testing.assert_allclose(times, np.arange(T) / 60.0, atol=1e-6)
    k = 5
    local = {}
    for ch in anim.channels:
        val = data(anim.samplers[ch.sampler].output)[k]
        local.setdefault(ch.target.node, {})[ch.target.path] = val
    world = {}

    def visit(i, parent):
        node = g.nodes[i]
        M = np.eye(4)
        q = local.get(i, {}).get("rotation", node.rotation or [0, 0, 0, 1])
        M[:3, :3] = _quat_matrix(np.asarray(q) / np.linalg.norm(q))
        M[:3, 3] = local.get(i, {}).get("translation", node.translation or [0, 0, 0])
        world[i] = parent @ M
        for c in node.children or []:
            visit(c, world[i])

    skin = g.skins[0]
    visit(skin.joints[0], np.eye(4))
    ibm = data(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    joint_mats = np.stack([world[j] @ ibm[n] for n, j in enumerate(skin.joints)])
    prim = g.meshes[0].primitives[0]
    P = data(prim.attributes.POSITION)
    Jn, Wt = data(prim.attributes.JOINTS_0).astype(int), data(prim.attributes.WEIGHTS_0)
    blend = np.einsum("nk,nkab->nab", Wt, joint_mats[Jn])
    V = np.einsum("nab,nb->na", blend[:, :3, :3], P) + blend[:, :3, 3]
    tracked = track.vertices[k] @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T  # Z→Y up
    assert np.linalg.norm(V - tracked, axis=1).mean() < 0.005
    assert np.ptp(P[:, 1]) == pytest.approx(np.ptp(template.V[:, 2]), abs=1e-6)  # Y is up
    assert len(skin.joints) == 31 and g.nodes[skin.joints[0]].name == "Hips"


def test_gltf_is_one_file_and_trimesh_opens_both(track_dir, glb, tmp_path):
    trimesh = pytest.importorskip("trimesh")
    res = export_track(track_dir, tmp_path / "walk.gltf", frames=slice(10, 14))
    assert res.format == "gltf" and res.n_frames == 4
    text = (tmp_path / "walk.gltf").read_text()
    assert '"uri":"data:application/octet-stream;base64,' in text
    for p in (glb[0], tmp_path / "walk.gltf"):
        scene = trimesh.load(p, force="scene")
        mesh = next(iter(scene.geometry.values()))
        assert len(mesh.vertices) == 5000


def _validator() -> tuple[str, str] | None:
    """node and the npm prefix holding node_modules/gltf-validator (MESHMOCAP_NODE_MODULES,
    where .ci/run installs it), or None."""
    node, base = shutil.which("node"), os.environ.get("MESHMOCAP_NODE_MODULES")
    if node and base and (Path(base) / "node_modules" / "gltf-validator").is_dir():
        return node, base
    return None


def test_glb_and_gltf_pass_the_khronos_validator(track_dir, glb, tmp_path):
    found = _validator()
    if found is None:
        pytest.skip(
            "node or gltf-validator is absent: npm install --prefix DIR gltf-validator, then "
            "set MESHMOCAP_NODE_MODULES=DIR (.ci/run does)"
        )
    node, base = found
    export_track(track_dir, tmp_path / "walk.gltf")
    tr = read_track(track_dir)  # and a morph-target animation, as transfer writes it
    write_gltf(tmp_path / "morph.glb", morph_gltf(tr.vertices[:3], tr.faces, np.arange(3) / 60))
    for path in (glb[0], tmp_path / "walk.gltf", tmp_path / "morph.glb"):
        env = {**os.environ, "NODE_PATH": str(Path(base) / "node_modules")}
        res = subprocess.run(
            [node, str(SCRIPTS / "gltf_validate.js"), str(path)],
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        assert res.returncode == 0, res.stderr
        report = json.loads(res.stdout)
        assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["messages"]


def test_c3d_reads_back_with_ezc3d(track_dir, track, tmp_path):
    import ezc3d

    res = export_track(track_dir, tmp_path / "walk.c3d", markers="lower_body")
    c = ezc3d.c3d(str(tmp_path / "walk.c3d"))
    labels = c["parameters"]["POINT"]["LABELS"]["value"]
    assert labels[:15] == list(EVAL_NAMES) and labels[15] == "LASI" and len(labels) == 31
    assert c["parameters"]["POINT"]["RATE"]["value"][0] == 60.0
    assert c["parameters"]["POINT"]["UNITS"]["value"] == ["mm"]
    assert c["header"]["points"]["first_frame"] == 10 and res.points == tuple(labels)
    pts = c["data"]["points"][:3].transpose(2, 1, 0)  # (T, P, 3) mm
    ok = np.arange(T) != 3
    np.testing.assert_allclose(pts[ok, :15], track.joints[ok] * 1000, atol=1e-3)
    assert np.isnan(pts[3]).all()  # the failed frame is a gap (residual −1)
    _, idx = marker_vertices(load_template("neutral_5k"))
    np.testing.assert_allclose(pts[ok, 15:], track.vertices[ok][:, idx] * 1000, atol=1e-3)


def test_trc_header_and_rows(track_dir, track, tmp_path):
    export_track(
        track_dir, tmp_path / "walk.trc", joints=["pelvis", "left_ankle"], frames=slice(10, 18, 2)
    )
    rows = list(csv.reader((tmp_path / "walk.trc").read_text().splitlines(), delimiter="\t"))
    assert rows[0][:3] == ["PathFileType", "4", "(X/Y/Z)"]
    info = dict(zip(rows[1], rows[2], strict=True))
    assert info["DataRate"] == "30" and info["NumFrames"] == "4" and info["Units"] == "mm"
    assert info["OrigDataStartFrame"] == "11" and info["NumMarkers"] == "2"
    assert [s for s in rows[3] if s] == ["Frame#", "Time", "pelvis", "left_ankle"]
    data = np.array([[float(x) for x in r] for r in rows[6:]])
    np.testing.assert_allclose(data[:, 1], np.array([10, 12, 14, 16]) / 60.0, atol=1e-6)
    ankle = data[:, 5:8] / 1000.0  # OpenSim: X = −y, Y = z, Z = −x
    truth = track.joints[[0, 2, 4, 6], EVAL_NAMES.index("left_ankle")]
    np.testing.assert_allclose(ankle, np.c_[-truth[:, 1], truth[:, 2], -truth[:, 0]], atol=1e-6)


def test_csv_wide_and_long(track_dir, track, tmp_path):
    export_track(track_dir, tmp_path / "wide.csv")
    export_track(track_dir, tmp_path / "long.csv", long=True, joints=["head"])
    wide = list(csv.DictReader((tmp_path / "wide.csv").read_text().splitlines()))
    assert len(wide) == T and wide[3]["healthy"] == "0" and wide[3]["failed"] == "1"
    assert wide[3]["message"] == "solver diverged" and wide[0]["lost"] == "0"
    assert float(wide[2]["time_s"]) == pytest.approx(12 / 60.0, abs=1e-6)
    got = np.array(
        [[float(r[f"{n}_{a}"] or "nan") for n in EVAL_NAMES for a in "xyz"] for r in wide]
    ).reshape(T, 15, 3)
    ok = np.arange(T) != 3
    np.testing.assert_allclose(got[ok], track.joints[ok], atol=1e-6)
    long = list(csv.DictReader((tmp_path / "long.csv").read_text().splitlines()))
    assert len(long) == T and {r["joint"] for r in long} == {"head"}
    for r in (*wide, *long):  # numbers everywhere, never NaN; the failed frame a gap
        gap = r["failed"] == "1"
        for key, value in r.items():
            if key in ("x", "y", "z") or key[-2:] in ("_x", "_y", "_z"):
                assert value == "" if gap else np.isfinite(float(value)), (key, value)
            elif key not in ("message", "joint"):
                assert np.isfinite(float(value)), (key, value)


def test_export_command_and_mistakes(track_dir, tmp_path, capsys):
    assert (
        main(["export", str(track_dir), "--out", str(tmp_path / "j.csv"), "--frames", "12:"]) == 0
    )
    assert "wrote" in capsys.readouterr().out
    assert len((tmp_path / "j.csv").read_text().splitlines()) == 1 + 6
    assert main(["export", str(track_dir), "--out", str(tmp_path / "j.xyz")]) == 2
    assert "cannot tell the format" in capsys.readouterr().err
    with pytest.raises(InputError, match="joints and markers select points"):
        export_track(track_dir, tmp_path / "a.bvh", joints=["head"])
    with pytest.raises(InputError, match="unknown joints"):
        export_track(track_dir, tmp_path / "a.csv", joints=["nose"])
    with pytest.raises(InputError, match="no track frame"):
        export_track(track_dir, tmp_path / "a.csv", frames=slice(100, 200))
    with pytest.raises(MeshmocapFileNotFoundError, match="does not exist"):
        export_track(track_dir, tmp_path / "nope" / "a.csv")


def test_a_bvh_s_fit_serves_the_glb_of_the_same_frames(track_dir, track, bvh, glb, tmp_path):
    """The rig's poses fitted for the BVH, given to the GLB of the same track (read once):
    the GLB's bytes as fitted anew; a fit of other frames or for a point format is refused."""
    res = bvh[1]
    assert res.fit is not None and len(res.fit.rotations) == len(track.frames)
    again = export_track(
        track, tmp_path / "w.glb", template=load_template("neutral_5k"), fit=res.fit
    )
    assert again.fit is res.fit and again.path.read_bytes() == glb[0].read_bytes()
    with pytest.raises(InputError, match="the fit given holds 8 frames, the export 3"):
        export_track(track, tmp_path / "a.glb", frames=slice(10, 13), fit=res.fit)
    with pytest.raises(InputError, match="a fit applies to bvh, gltf and glb, not csv"):
        export_track(track, tmp_path / "a.csv", fit=res.fit)
    assert export_track(track, tmp_path / "a.csv").fit is None


def test_frame_rate_and_rows(track):
    assert track_fps(track) == (60.0, "capture.json")
    assert track_fps(track, 25.0) == (25.0, "given")
    assert track_rows(track, slice(11, 16, 2)).tolist() == [1, 3, 5]


def test_lower_body_markers_sit_where_expected(template):
    names, idx = marker_vertices(template, "lower_body")
    assert len(names) == 16 and names[0] == "LASI" and names[-1] == "RTOE"
    assert len(set(idx.tolist())) == 16
    P = dict(zip(names, template.V[idx], strict=True))
    for side, s in (("L", 1), ("R", -1)):
        z = [P[side + n][2] for n in ("ASI", "THI", "KNE", "TIB", "ANK")]
        assert np.all(np.diff(z) < 0)  # top to bottom
        assert P[side + "ASI"][1] < P[side + "PSI"][1]  # front (−Y) and back
        assert P[side + "TOE"][1] < P[side + "HEE"][1]
        assert s * P[side + "KNE"][0] > 0.1  # lateral
    for n in ("ASI", "KNE", "ANK", "TOE"):  # the template is near-symmetric: so are they
        assert np.linalg.norm(P["L" + n] * [-1, 1, 1] - P["R" + n]) < 0.03


def test_a_track_of_an_estimated_subject_exports_with_its_own_template(track_dir, tmp_path):
    """The default track of a real capture deforms an estimated body saved in the track
    folder (track.json: template_file): exports find it there, with no template argument."""
    from meshmocap.body.template import save_template

    out = tmp_path / "track"
    shutil.copytree(track_dir, out)
    body = load_template("neutral_5k")
    save_template(out / "subject.npz", replace(body, name="subject"))
    meta = json.loads((out / "track.json").read_text())
    meta.update(template="subject", template_source="estimated", template_file="subject.npz")
    (out / "track.json").write_text(json.dumps(meta))
    res = export_track(out, tmp_path / "walk.bvh")
    assert res.n_frames == T and res.vertex_error_mm < 5.0  # same body, same fit as bundled
    (out / "subject.npz").unlink()
    with pytest.raises(MeshmocapFileNotFoundError, match=r"subject\.npz, which is missing"):
        export_track(out, tmp_path / "walk2.bvh")
    assert export_track(out, tmp_path / "walk.csv").n_frames == T  # points need no template
