"""glTF out and glTF / FBX in (lmm.data.gltf_write, lmm.data.gltf, lmm.data.fbx, lmm.data.motion_files).

Checked against files and programs nobody here wrote: Debian's assimp-testmodels (real glTF and FBX files
with animated skeletons; skipped when /usr/share/assimp/models is absent) and Blender's own glTF and FBX
importers (skipped without ``blender``). The optional readers are skipped when their extra is not installed.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lmm.data import bvh
from lmm.data.motion_files import MOTION_UNIT_M, MotionFileError, load_motion
from lmm.errors import InputError

pygltflib = pytest.importorskip("pygltflib")

ROOT = Path(__file__).resolve().parents[3]
TAKE = ROOT / "lmm/data/lafan1/multipleActions1_subject1.bvh.gz"
ASSIMP = Path("/usr/share/assimp/models")
needs_assimp = pytest.mark.skipif(not ASSIMP.is_dir(), reason="Debian's assimp-testmodels is not installed "
                                  "(apt-get install assimp-testmodels; .ci/run installs it)")
needs_blender = pytest.mark.skipif(shutil.which("blender") is None, reason="Blender is not installed")
#: (file under ASSIMP, joints, frames, fps) of the animated skeletons that read
READ = [("glTF2/simple_skin/simple_skin.gltf", 2, 166, 30.0),
        ("FBX/animation_with_skeleton.fbx", 16, 21, 24.0),
        ("FBX/huesitos.fbx", 11, 40, 25.0)]
#: (file under ASSIMP, what the one line says) of some that are refused
REFUSED = [("FBX/box.fbx", "has no skeleton"),
           ("FBX/spider.fbx", "has no skeleton"),
           ("glTF2/BoxTextured-glTF-Binary/BoxTextured.glb", "has no skin"),
           ("glTF2/glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf", "has no skin"),
           ("glTF2/wrongTypes/badNumber.gltf", "not a glTF 2.0 file"),
           ("FBX/transparentTest.fbx", "not a readable FBX file")]


@pytest.fixture(scope="module")
def clip():
    """20 s of a LAFAN1 take (centimetres, 30 fps)."""
    return bvh.load(TAKE).slice(0, 600)


@pytest.fixture(scope="module")
def glb(clip, tmp_path_factory):
    from lmm.data.gltf_write import save_glb

    out = tmp_path_factory.mktemp("gltf") / "clip.glb"
    save_glb(out, clip, 0.01)
    return out


def _one_line(e: Exception, path) -> str:
    text = str(e)
    assert "\n" not in text and str(path) in text, text
    return text


def test_the_glb_holds_the_skeleton_skin_and_animation_as_another_reader_sees_them(clip, glb):
    g = pygltflib.GLTF2().load(str(glb))
    assert [n.name for n in g.nodes[:clip.n_joints]] == clip.names
    assert g.skins[0].joints == list(range(clip.n_joints))
    channels = g.animations[0].channels
    assert sorted(c.target.node for c in channels if c.target.path == "rotation") == list(range(clip.n_joints))
    assert [c.target.node for c in channels if c.target.path == "translation"] == [0]      # the hips move
    times = g.accessors[g.animations[0].samplers[0].input]
    assert times.count == clip.n_frames and times.max[0] == pytest.approx((clip.n_frames - 1) * clip.frame_time)
    assert g.meshes[0].name == "capsules" and g.nodes[-1].skin == 0
    # capsules sized by the standing character's height, not the rest pose's (LAFAN1's lies along x: 6 cm tall)
    box = g.accessors[g.meshes[0].primitives[0].attributes.POSITION]
    assert min(hi - lo for lo, hi in zip(box.min, box.max)) > 0.15
    # metres: the hips' rest offset is the file's in centimetres / 100
    assert g.nodes[0].translation == pytest.approx(list(clip.offsets[0] * 0.01), abs=1e-9)


def test_round_trip_bvh_to_glb_to_our_reader_keeps_every_joint_within_0_1_mm(clip, glb):
    back = load_motion(glb)
    assert back.names == clip.names and list(back.parents) == list(clip.parents)
    assert back.n_frames == clip.n_frames and back.fps == pytest.approx(clip.fps, rel=1e-6)
    error = np.abs(back.global_positions() * MOTION_UNIT_M - clip.global_positions() * 0.01).max()
    assert error < 1e-4, error


def test_export_gltf_command_without_mesh(clip, tmp_path):
    from app.cli import main

    src = tmp_path / "clip.bvh"
    bvh.save(src, clip.slice(0, 30))
    out = tmp_path / "out.glb"
    assert main(["export-gltf", str(src), "--out", str(out), "--mesh", "none"]) == 0
    g = pygltflib.GLTF2().load(str(out))
    assert not g.meshes and len(g.nodes) == clip.n_joints


def test_broken_files_are_one_line_naming_the_file(glb, tmp_path):
    cut = tmp_path / "truncated.glb"
    cut.write_bytes(glb.read_bytes()[:5000])
    not_gltf = tmp_path / "other.gltf"
    not_gltf.write_text(json.dumps({"hello": [1, 2, 3]}))
    still = tmp_path / "still.glb"
    g = pygltflib.GLTF2().load(str(glb))
    g.animations = []
    g.save(str(still))
    garbage = tmp_path / "garbage.fbx"
    garbage.write_bytes(b"Kaydara FBX Binary  \x00\x1a\x00" + bytes(range(256)) * 4)
    cases = [(cut, "truncated"), (not_gltf, "not a glTF 2.0 file"), (still, "has no animation")]
    if _has("ufbx"):
        cases.append((garbage, "not a readable FBX file"))
    for path, says in cases:
        with pytest.raises(MotionFileError) as e:
            load_motion(path)
        assert says in _one_line(e.value, path)


def test_a_bad_file_through_a_command_is_one_line_and_exit_1(tmp_path):
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00")
    r = subprocess.run([sys.executable, "-m", "app.cli", "export-gltf", str(bad), "--out", str(tmp_path / "o.glb")],
                       capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and str(bad) in r.stderr, r.stderr


def _has(module: str) -> bool:
    try:
        __import__(module)
    except ImportError:
        return False
    return True


def _skip_fbx_without_ufbx(name: str) -> None:
    if name.lower().endswith(".fbx") and not _has("ufbx"):
        pytest.skip("ufbx (the formats extra) is not installed")


@needs_assimp
@pytest.mark.parametrize("name,joints,frames,fps", READ)
def test_real_animated_skeletons_read(name, joints, frames, fps):
    _skip_fbx_without_ufbx(name)
    anim = load_motion(ASSIMP / name)
    assert (anim.n_joints, anim.n_frames, anim.fps) == (joints, frames, pytest.approx(fps))
    assert np.isfinite(anim.global_positions()).all() and np.ptp(anim.motion, axis=0).max() > 0     # it moves


@needs_assimp
@pytest.mark.parametrize("name,says", REFUSED)
def test_real_files_without_an_animated_skeleton_are_refused_in_one_line(name, says):
    _skip_fbx_without_ufbx(name)
    with pytest.raises(MotionFileError) as e:
        load_motion(ASSIMP / name)
    assert says in _one_line(e.value, ASSIMP / name)


def _blender_joints(path: Path, fps: float, frames: int, tmp_path: Path) -> dict:
    out = tmp_path / "blender.json"
    script = Path(__file__).with_name("blender_joints.py")
    subprocess.run(["blender", "-b", "--factory-startup", "--python", str(script), "--", str(path), str(out), repr(fps),
                    str(frames)], check=True, capture_output=True, timeout=120)
    return json.loads(out.read_text())["joints"]


@pytest.mark.slow
@needs_blender
def test_blender_imports_our_glb_with_the_joints_where_the_bvh_has_them(clip, tmp_path):
    from lmm.data.gltf_write import save_glb

    short = clip.slice(0, 90)
    path = tmp_path / "short.glb"
    save_glb(path, short, 0.01)
    joints = _blender_joints(path, short.fps, short.n_frames, tmp_path)
    pos = short.global_positions() * 0.01
    error = max(np.abs(np.array(joints[n]) - pos[:, j]).max() for j, n in enumerate(short.names))
    assert error < 1e-3, error


@pytest.mark.slow
@needs_blender
@needs_assimp
@pytest.mark.parametrize("name", [n for n, *_ in READ])
def test_our_readers_agree_with_blenders_import_of_real_files_within_1_mm(name, tmp_path):
    _skip_fbx_without_ufbx(name)
    anim = load_motion(ASSIMP / name)
    joints = _blender_joints(ASSIMP / name, anim.fps, anim.n_frames, tmp_path)
    pos = anim.global_positions() * MOTION_UNIT_M
    error = max(np.abs(np.array(joints[n]) - pos[:, j]).max() for j, n in enumerate(anim.names))
    assert error < 1e-3, error


#: tests/corpus/motion/: bad glTF and FBX files (made once from tests/corpus/good/walk.bvh or by hand) -> what
#: the one line says
CORPUS = ROOT / "tests/corpus/motion"
BAD_FILES = {"truncated.glb": "a truncated glb", "no_animation.glb": "has no animation",
             "not_gltf.gltf": "not a glTF 2.0 file", "no_skin.gltf": "has no skin",
             "garbage.fbx": "not a readable FBX file", "no_skeleton.fbx": "has no skeleton"}


def test_the_corpus_of_bad_motion_files_is_one_line_in_every_command(tmp_path, monkeypatch, capsys):
    from app.cli import main

    monkeypatch.setenv("LMM_STUDIO_CACHE", str(tmp_path / "cache"))
    good = json.loads((ROOT / "tests/corpus/good/manifest.json").read_text())
    assert sorted(p.name for p in CORPUS.iterdir()) == sorted(BAD_FILES)
    for name, says in BAD_FILES.items():
        if name.endswith(".fbx") and not _has("ufbx"):
            continue
        path = CORPUS / name
        manifest = tmp_path / f"{name}.json"
        manifest.write_text(json.dumps(dict(good, name="motion-corpus", clips=[{"file": str(path)}])))
        for argv in (["view", str(path), "--screenshot", str(tmp_path / "shot.png")],
                     ["build-db", "--manifest", str(manifest)],
                     ["check-data", "--manifest", str(manifest), "--quiet"],
                     ["export-gltf", str(path), "--out", str(tmp_path / "out.glb")]):
            code = main(argv)
            err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
            assert code == 1 and len(err) == 1 and name in err[0] and says in err[0], (argv, code, err)


def test_a_glb_in_a_manifest_builds_the_database_its_bvh_builds(tmp_path):
    """glTF in, where a manifest takes a BVH: the exported walk gives the BVH's database (positions to float32's
    precision of a 0.1 mm round trip)."""
    from lmm.data.build import build
    from lmm.data.gltf_write import save_glb
    from lmm.data.manifest import load_manifest

    walk = ROOT / "tests/corpus/good/walk.bvh"
    glb = tmp_path / "walk.glb"
    save_glb(glb, bvh.load(walk), 0.01, mesh="none")
    good = json.loads((ROOT / "tests/corpus/good/manifest.json").read_text())
    dbs = []
    for f in (walk, glb):
        m = tmp_path / f"{f.suffix[1:]}.json"
        m.write_text(json.dumps(dict(good, name=f"db-{f.suffix[1:]}", clips=[dict(good["clips"][0], file=str(f))])))
        dbs.append(build(load_manifest(m)))
    a, b = dbs
    assert a.names == b.names and a.positions.shape == b.positions.shape
    assert np.abs(a.positions - b.positions).max() < 1e-4          # metres
    assert (a.contacts == b.contacts).all()


def test_a_missing_formats_extra_is_one_line_naming_the_extra(glb, tmp_path, monkeypatch, capsys):
    from app.cli import main
    from lmm.data.motion_files import MissingExtra

    monkeypatch.setitem(sys.modules, "pygltflib", None)
    monkeypatch.setitem(sys.modules, "ufbx", None)
    for path in (glb, ASSIMP / "FBX/huesitos.fbx"):
        with pytest.raises(MissingExtra) as e:
            load_motion(path)
        assert "'.[formats]'" in _one_line(e.value, path)
    assert main(["export-gltf", str(TAKE), "--out", str(tmp_path / "x.glb")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pygltflib" in err[0] and "'.[formats]'" in err[0], err


def test_the_capsule_body_is_closed_and_faces_outward(clip):
    """Every triangle of the skinned body has an area and winds counter-clockwise seen from outside (glTF's
    front face), and each vertex is bound to one joint that exists."""
    from lmm import kinematics
    from lmm.data.gltf_write import capsule_body

    rest = kinematics.forward_kinematics(np.tile([1.0, 0, 0, 0], (1, clip.n_joints, 1)),
                                         clip.offsets[None] * 0.01, clip.parents)[1][0]
    v, n, t, joints = capsule_body(clip.names, clip.parents, rest, 1.7)
    face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert np.linalg.norm(face, axis=1).min() > 0
    assert (np.sum(face * n[t].mean(axis=1), axis=1) > 0).all()
    assert joints.min() >= 0 and joints.max() < clip.n_joints


def test_a_session_is_replayed_and_exported(tmp_path, monkeypatch):
    from app.cli import main

    monkeypatch.setenv("LMM_STUDIO_CACHE", str(ROOT / ".cache/lmm-studio"))
    session = tmp_path / "run.lmmsession"
    assert main(["run", "--controller", "mm", "--input", "builtin:circle", "--seconds", "1", "--session", str(session),
                 "--quiet"]) == 0
    out = tmp_path / "run.glb"
    assert main(["export-gltf", str(session), "--out", str(out), "--mesh", "none"]) == 0
    assert main(["replay", str(session), "--record", str(tmp_path / "run.bvh")]) == 0
    a, b = load_motion(out), bvh.load(tmp_path / "run.bvh")
    assert (a.n_frames, a.names) == (b.n_frames, b.names) and a.fps == pytest.approx(60.0, rel=1e-6)
    assert np.abs(a.global_positions() - b.global_positions()).max() < 1e-2       # centimetres: 0.1 mm


def test_the_studios_reference_clip_reads_a_glb_as_its_bvh(clip, glb, tmp_path):
    from app.reference_clip import load_reference_clip

    src = tmp_path / "clip.bvh"
    bvh.save(src, clip)
    a, b = load_reference_clip(src), load_reference_clip(glb)
    assert a.names == b.names and a.positions.shape == b.positions.shape
    assert np.abs(a.positions - b.positions).max() < 1e-4                   # metres


def _set_time(g, index_from_end: int, value: float) -> None:
    import struct

    blob = bytearray(g.binary_blob())
    times = g.accessors[g.animations[0].samplers[0].input]
    view = g.bufferViews[times.bufferView]
    struct.pack_into("<f", blob, view.byteOffset + 4 * (times.count - index_from_end), value)
    g.set_binary_blob(bytes(blob))


HOSTILE = {
    "a NaN keyframe time": (lambda g: _set_time(g, 2, float("nan")), "not finite"),
    "a keyframe at 10^9 s": (lambda g: _set_time(g, 1, 1e9), "joint-frames"),
    "a cycle in the joints": (lambda g: setattr(g.nodes[1], "children", (g.nodes[1].children or []) + [0]), "cycle"),
    "an accessor that does not exist": (lambda g: setattr(g.animations[0].samplers[0], "output", 999), "accessor 999"),
    "a skin joint that does not exist": (lambda g: g.skins[0].joints.append(999), "does not exist"),
    "a sampler that does not exist": (lambda g: setattr(g.animations[0].channels[0], "sampler", 999), "sampler"),
}


@pytest.mark.parametrize("what", sorted(HOSTILE))
def test_hostile_gltf_fields_are_one_line(what, glb, tmp_path):
    change, says = HOSTILE[what]
    g = pygltflib.GLTF2().load(str(glb))
    change(g)
    path = tmp_path / "hostile.glb"
    g.save(str(path))
    with pytest.raises(MotionFileError) as e:
        load_motion(path)
    assert says in _one_line(e.value, path)


@pytest.mark.parametrize("name", ["fifo.glb", "fifo.gltf", "fifo.fbx"])
def test_a_fifo_named_like_a_motion_file_is_one_line_and_never_blocks(name, tmp_path):
    import os

    if name.endswith(".fbx") and not _has("ufbx"):
        pytest.skip("ufbx (the formats extra) is not installed")
    path = tmp_path / name
    os.mkfifo(path)
    with pytest.raises(InputError) as e:
        load_motion(path)
    assert "FIFO" in _one_line(e.value, path)


@needs_assimp
@pytest.mark.parametrize("name", [n for n, *_ in READ])
def test_real_files_survive_our_glb_round_trip(name, tmp_path):
    """FBX or glTF in, glTF out, glTF in: the same joints at the same frames (within 0.1 mm)."""
    from lmm.data.gltf_write import save_glb

    _skip_fbx_without_ufbx(name)
    anim = load_motion(ASSIMP / name)
    out = tmp_path / "again.glb"
    save_glb(out, anim, MOTION_UNIT_M)
    back = load_motion(out)
    assert back.names == anim.names and back.n_frames == anim.n_frames
    assert np.abs(back.global_positions() - anim.global_positions()).max() * MOTION_UNIT_M < 1e-4
