"""What a newcomer once got silently, or in the library's words (issue 47), in-process through
``meshmocap.cli.main``: each case ends in one line naming the file or the argument, what
was expected and what was found, and leaves what the user had unchanged; a frame that is
not the capture's (another performer's mesh, an OBJ cut off in its faces) is skipped and
flagged with the reason; a capture folder is never written to, read-only or not."""

from __future__ import annotations

import hashlib
import shutil
import stat
from pathlib import Path

import pytest

from meshmocap.cli import main

ICP = ["--method", "articulated_icp", "--max-iter", "1"]


@pytest.fixture(autouse=True)
def _quiet_progress(monkeypatch):
    """No progress or phase lines on stderr, however slow a loaded machine runs: the
    messages checked here are exact."""
    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "3600")
    monkeypatch.setattr("meshmocap._progress.PHASE_SECONDS", 3600.0)


def snapshot(folder: Path) -> dict[str, str]:
    """Every file and folder under ``folder`` (relative path → SHA-256 of the bytes, or
    ``"dir"``): equal before and after means nothing was added, removed or changed."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        out[rel] = "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _read_only(folder: Path) -> None:
    for p in [*folder.rglob("*"), folder]:
        mode = p.stat().st_mode
        p.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


def _writable(folder: Path) -> None:
    for p in [folder, *folder.rglob("*")]:
        p.chmod(p.stat().st_mode | stat.S_IWUSR)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["mesh_folder", "capture_folder"])
def test_a_read_only_capture_tracks_to_the_end_and_is_left_byte_identical(
    kind, mesh_folder, small_walk, tmp_path, capsys
):
    src = mesh_folder if kind == "mesh_folder" else small_walk.path
    cap = tmp_path / "ro" / src.name
    shutil.copytree(src, cap)
    before = snapshot(cap)
    _read_only(cap)  # as root chmod stops nothing: the snapshot is the proof
    try:
        argv = ["track", str(cap), *ICP, "--frames", "0:3", "--template", "neutral_5k"]
        assert main([*argv, "--out", str(tmp_path / "t")]) == 0, capsys.readouterr().err
        argv = ["eval", str(cap), str(tmp_path / "t"), "--no-silhouettes", "--surface-frames"]
        assert main([*argv, "1", "--out", str(tmp_path / "e")]) == 0
    finally:
        _writable(cap)
    assert snapshot(cap) == before
    assert "tracked 3 frames" in capsys.readouterr().out


# --------------------------------------------- frames that are not the capture's (1, 4)


def _obj_folder(mesh_folder: Path, tmp: Path) -> Path:
    """The clean 4D capture as OBJ files (its 5 frames, then back through 3, 2, 1),
    damaged as a newcomer's was: frame 1 cut off in the middle of a face line, frame 2
    another performer's mesh (the 12k-vertex body among 5k-vertex frames), frame 3 cut
    off at the end of a face line."""
    from meshmocap.body.template import load_template
    from meshmocap.io.meshes import read_mesh, write_mesh

    out = tmp / "cap"
    out.mkdir()
    files = sorted(mesh_folder.glob("*.ply"))
    for k, p in enumerate([*files, *files[-2:0:-1]]):
        write_mesh(out / f"frame_{k:03d}.obj", *read_mesh(p))
    for k, tail in ((1, "f 3824 3"), (3, "")):
        lines = (out / f"frame_{k:03d}.obj").read_text().splitlines()
        faces = [i for i, line in enumerate(lines) if line.startswith("f ")]
        kept = lines[: faces[len(faces) // 3]] + ([tail] if tail else [])
        (out / f"frame_{k:03d}.obj").write_text("\n".join(kept) + ("" if tail else "\n"))
    other = load_template("neutral")
    write_mesh(out / "frame_002.obj", other.V + [0.3, 0.0, 0.0], other.F)
    return out


@pytest.fixture(scope="module")
def damaged(mesh_folder, tmp_path_factory):
    """``(capture, its snapshot, track folder, stdout, stderr)`` of ``track`` on
    :func:`_obj_folder`."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("damaged")
    cap = _obj_folder(mesh_folder, tmp)
    before = snapshot(cap)
    out, err = io.StringIO(), io.StringIO()
    argv = ["track", str(cap), *ICP, "--template", "neutral_5k", "--out", str(tmp / "t")]
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main(argv) == 0, err.getvalue()
    return cap, before, tmp / "t", out.getvalue(), err.getvalue()


@pytest.mark.slow
def test_frames_of_another_performer_or_cut_off_are_skipped_and_named(damaged):
    import json

    from meshmocap.io.results import read_track

    cap, before, trk, out, err = damaged
    expected = "expected 5000 vertices and 9996 triangles as in the other frames of this "
    expected += "fixed-connectivity sequence (another performer's mesh, or a file cut off or "
    expected += "damaged)"
    lines = sorted(Path(cap / "frame_001.obj").read_text().splitlines())
    assert "f 3824 3" in lines
    reasons = {
        "1": f"{cap}/frame_001.obj: line ",  # the line number: the file's own, 1-based
        "2": f"{cap}/frame_002.obj: a mesh of 12411 vertices and 24818 triangles; {expected}",
        "3": f"{cap}/frame_003.obj: a mesh of 5000 vertices and 3332 triangles; {expected}",
    }
    skipped = json.loads((trk / "track.json").read_text())["skipped"]
    assert sorted(skipped) == ["1", "2", "3"]
    assert skipped["1"].endswith(
        "'f 3824 3' is a face of 2 vertices, expected 3 or more (the file is cut off there)"
    )
    assert skipped["1"].startswith(reasons["1"])
    assert skipped["2"] == reasons["2"] and skipped["3"] == reasons["3"]
    t = read_track(trk)
    assert t.flags[1:4] == (("missing",),) * 3 and t.messages[2] == reasons["2"]
    assert "3 flagged unhealthy (3 missing)" in out
    warned = [line for line in err.splitlines() if line.startswith("meshmocap: warning:")]
    assert warned == [
        "meshmocap: warning: 3 frames without a usable observation (skipped, coasted "
        f"across), first 1: {skipped['1']}"
    ]
    assert snapshot(cap) == before


@pytest.mark.slow
def test_eval_and_the_report_of_a_skipped_frame_keep_the_per_vertex_error(
    damaged, tmp_path, capsys
):
    from meshmocap import api
    from meshmocap.apps.report.notes import frame_rows

    cap, before, trk, _, _ = damaged
    assert main(["eval", str(cap), str(trk), "--surface-frames", "2"]) == 0
    out = capsys.readouterr().out
    assert "Per-vertex error, mm (5000 vertices; 5 frames, 0 failed, 3 skipped)" in out
    ev = api.evaluate(cap, trk, surface_frames=0)
    rows = {r[0]: r for r in frame_rows(ev, api.open_track(trk).data)}
    assert rows["flagged: missing"][1:3] == (3, "1–3")
    assert "frame_002.obj: a mesh of 12411 vertices" in rows["flagged: missing"][3]
    assert snapshot(cap) == before


def _faces(n_vertices: int):
    import numpy as np

    k = np.arange(n_vertices - 2)
    return np.stack([k, k + 1, k + 2], axis=1)


@pytest.mark.parametrize(
    ("layout", "fixed"),
    [
        ("AAAAA", True),
        ("AABAA", True),  # one file differs: the others' connectivity
        ("AAABB", False),  # remeshed halfway: no single connectivity
        ("ABCDE", False),  # a mesh per frame (visual hulls)
        ("AB", False),
        ("AAB", True),
        ("A", False),  # nothing to compare
        ("PPPPP", False),  # point clouds
    ],
)
def test_a_fixed_connectivity_is_what_all_files_or_all_but_one_share(tmp_path, layout, fixed):
    import numpy as np

    from meshmocap.io.capture import SequenceCapture
    from meshmocap.io.meshes import write_mesh

    rng = np.random.default_rng(3)
    for k, c in enumerate(layout):
        V = rng.normal(size=(12 + "ABCDE".index(c) if c != "P" else 12, 3))
        if c == "P":
            (tmp_path / f"f_{k}.xyz").write_text("\n".join(" ".join(map(str, v)) for v in V))
        else:
            write_mesh(tmp_path / f"f_{k}.ply", V, _faces(len(V)))
    cap = SequenceCapture(tmp_path)
    assert (cap.connectivity is not None) == fixed
    odd = [k for k, c in enumerate(layout) if c != "A"]
    missing = [k for k in range(len(layout)) if cap[k].missing]
    assert missing == (odd if fixed else [])


# ------------------------------------------------------------- --out among the inputs (2, 3)


@pytest.mark.parametrize("how", ["folder", "inside", "glob", "file"])
def test_an_out_among_the_inputs_is_refused_and_nothing_written(mesh_folder, tmp_path, capsys, how):
    cap = tmp_path / "selfout"
    shutil.copytree(mesh_folder, cap)
    before = snapshot(cap)
    source, out, says = {
        "folder": (cap, cap, f"is the capture folder {cap}"),
        "inside": (cap, cap / "t", f"lies in the capture folder {cap}"),
        "glob": (f"{cap}/*.ply", cap, f"is the folder of the glob {cap}/*.ply"),
        "file": (cap / "00000.ply", cap, f"is the folder holding the input {cap}/00000.ply"),
    }[how]
    capsys.readouterr()
    assert main(["track", str(source), "--out", str(out)]) == 2
    _one_error_line(
        capsys,
        f"track: --out {out}: {says}, which track reads; expected a folder outside it (the "
        "input is never written to)",
    )
    assert snapshot(cap) == before


def test_a_folder_mixing_formats_suggests_the_glob_of_most_of_its_files(tmp_path, capsys):
    import numpy as np

    for k in range(3):
        (tmp_path / f"m_{k}.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    np.save(tmp_path / "faces.npy", np.zeros((1, 3), np.int32))  # a stray array among them
    capsys.readouterr()
    assert main(["track", str(tmp_path), "--out", str(tmp_path.parent / "t")]) == 2
    _one_error_line(
        capsys,
        f"{tmp_path}: folder mixes ['.npy', '.obj'] (1 .npy, 3 .obj); pass a glob "
        f"like '{tmp_path}/*.obj'",
    )


@pytest.mark.slow
def test_an_out_holding_another_captures_track_is_refused_before_its_body_is_reused(
    damaged, mesh_folder, capsys
):
    _, _, trk, _, _ = damaged
    before = snapshot(trk)
    capsys.readouterr()
    assert main(["track", str(mesh_folder), *ICP, "--out", str(trk)]) == 2
    run = capsys.readouterr()
    assert "reused" not in run.out and "template" not in run.out
    _one_error_line(
        capsys,
        f"track: --out {trk} holds the track of another capture ({trk.parent / 'cap'}); "
        f"expected a new folder, or a track of {mesh_folder} to resume: give another --out, "
        "or --restart to track over it",
        err=run.err,
    )
    assert snapshot(trk) == before


def test_the_python_api_refuses_another_captures_track_in_its_own_words(mesh_folder, tmp_path):
    import json

    from meshmocap import api
    from meshmocap.errors import OutputPathError

    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "track.json").write_text(json.dumps({"capture": "/data/walk"}))
    with pytest.raises(OutputPathError) as info:
        api.track(str(mesh_folder), out=tmp_path / "t", method="articulated_icp")
    assert str(info.value) == (
        f"track: out {tmp_path / 't'} holds the track of another capture (/data/walk); "
        f"expected a new folder, or a track of {mesh_folder} to resume: give another out, "
        "or resume=False to track over it"
    )


def _one_error_line(capsys, message: str, *, err: str | None = None) -> None:
    err = capsys.readouterr().err if err is None else err
    lines = [x for x in err.splitlines() if not x.startswith("meshmocap: loading")]
    assert len(lines) == 1 and lines[0].startswith("meshmocap: error: "), err
    assert message in lines[0], err


# ------------------------------------------------------- messages in the CLI's words (5)


def test_a_nan_vertex_is_named_by_its_line_and_one_based_number(tmp_path, capsys):
    lines = ["# a hand-made file", *(f"v {k} 0 {k % 7}" for k in range(120))]
    lines[100] = "v 0.1 nan 0.2"  # vertex 100, line 101
    lines += [f"f {k + 1} {k + 2} {k + 3}" for k in range(118)]
    (tmp_path / "a_0.obj").write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    assert main(["track", str(tmp_path / "a_0.obj"), "--out", str(tmp_path / "t")]) == 2
    _one_error_line(
        capsys,
        f"{tmp_path}/a_0.obj: 1 vertex is NaN or infinite (first: vertex 100 of the file, "
        "line 101)",
    )


def test_a_point_cloud_in_obj_files_is_named_in_the_cli_words(tmp_path, capsys):
    for k in range(2):
        (tmp_path / f"p_{k}.obj").write_text("".join(f"v {i} 0 {i % 5}\n" for i in range(60)))
    capsys.readouterr()
    assert main(["track", str(tmp_path), "--out", str(tmp_path.parent / "t")]) == 2
    _one_error_line(
        capsys,
        "p_0.obj: no triangles (a file cut off before its faces, or a point cloud, which is "
        "read from .ply, .xyz, .npy or .pcd files)",
    )


# --------------------------------------------------------------- track --help (7)


def test_track_help_states_every_default(capsys):
    from meshmocap.cli import build_parser
    from meshmocap.cli.track import DEFAULTS
    from meshmocap.trackers.registry import resolved_options

    parser = build_parser()
    track = parser._subparsers._group_actions[0].choices["track"]
    quiet = {"help", "out", "capture"}  # no default: asked for
    for action in track._actions:
        if action.dest in quiet or action.help == "==SUPPRESS==" or action.nargs == 0:
            continue
        assert "default" in (action.help or ""), action.dest
    assert main(["track", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for flag, value in (
        ("--method", "default: patch"),
        ("--n-patches", "default 200"),
        ("--classifier", "default logistic"),
        ("--keep-fraction", "default 1: all"),
        ("--max-iter", "default 8 for the patch tracker, 20 for articulated_icp"),
    ):
        assert value in text.split(flag, 2)[2].split(" --")[0], flag
    patch, icp = resolved_options("patch"), resolved_options("articulated_icp")
    options = {
        "n_patches": patch.n_patches,
        "classifier": patch.classifier,
        "keep_fraction": patch.keep_fraction,
        "max_iter": patch.max_iter,
        "icp_max_iter": icp.max_iter,
    }
    assert options == DEFAULTS
