"""Issue 36's corpus cases that need a prepared state or environment rather than a bad file argument:
damaged derived arrays (``<database>.derived/*.npy``) of each kind, hand-made database caches whose
arrays disagree, a missing home folder, and a studio
that cannot open its window (a display no X server answers at, an X server without GLX, a graphics
driver that cannot be loaded).

Each case runs in the driver like any other (time, memory, traceback, nothing left behind, inputs
unchanged), with two hooks the driver calls around it: :func:`before` (damage the cache the case reads,
from a pristine copy made once per job by :func:`prepare_derived`) and :func:`after` (the right output:
the recording or coverage JSON equal to the one made from the intact cache, every cached array intact
again, the fallback home's cache written). ``after`` returns what is wrong, as lines.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

CORPUS = Path(__file__).resolve().parent
ROOT = CORPUS.parents[1]
GOOD = CORPUS / "good"

# ---- damaged derived arrays --------------------------------------------------------------------------

#: every kind of derived array a command line reads (lmm.data.derived.cached callers; the studio's
#: compressor_latents needs the shipped database and is read through the same ``cached``)
KINDS = ("features", "root_local_velocities", "range_contact_heights", "default_start_frame",
         "source_ground_skating")
#: damage -> (what, expectation): "note" = exit 0 and one "damaged cached array" note; "accept" = exit 0
#: and no line but notes and warnings (an entry without its checksum is computed again without a note:
#: older code wrote none); build-db --rebuild is "accept" (one note per damaged array it read)
DAMAGES = {
    "empty": ("a 0-byte file (EOFError in run, coverage and build-db --rebuild)", "note"),
    "flip": ("one bit of its last value flipped (a different recording, exit 0)", "note"),
    "nan": ("a NaN written into it (a different recording, exit 0)", "note"),
    "truncated": ("cut to half its bytes", "note"),
    "wrong_shape": ("an array of another shape (3 rows) in its place", "note"),
    "not_npy": ("text in place of the array", "note"),
    "crc_garbage": ("its checksum file holds no checksum", "note"),
    "no_crc": ("its checksum file removed", "accept"),
    "consistent_wrong_shape": ("an array of another shape, its checksum written to match", "note"),
    "consistent_nan": ("a NaN written into it, its checksum written to match", "note"),
}
#: a NaN in range_contact_heights is what it legitimately holds where a range has no contact frames
NOT_A_DAMAGE = {("range_contact_heights", "nan"), ("range_contact_heights", "consistent_nan")}

_RUN = ["run", "--manifest", "{T}/manifest.json", "--input", "builtin:circle", "--seconds", "2", "--quiet"]


def derived_cases() -> list[tuple]:
    """(id, command, argv, expect, what, damage spec, after spec) of every derived-array case. ``{T}``: the
    job's folder of inputs (watched), ``{O}``: its output folder, ``{C}``: its cache."""
    out = []
    for damage, (what, expect) in DAMAGES.items():
        for kind in KINDS:
            if (kind, damage) in NOT_A_DAMAGE:
                continue
            out.append((f"derived-run-{kind}-{damage}", "run", _RUN + ["--record", f"{{O}}/{kind}-{damage}.bvh"],
                        expect, f"run on a cache whose {kind} array is {what}", {"kinds": [kind], "damage": damage},
                        {"same": [[f"{{O}}/{kind}-{damage}.bvh", "{O}/reference.bvh"]], "intact": True}))
        out.append((f"derived-coverage-features-{damage}", "coverage",
                    ["coverage", "--manifest", "{T}/manifest.json", "--json", f"{{O}}/coverage-{damage}.json"],
                    expect, f"coverage on a cache whose features array is {what}",
                    {"kinds": ["features"], "damage": damage},
                    {"same": [[f"{{O}}/coverage-{damage}.json", "{O}/reference.json"]], "intact": True}))
        out.append((f"derived-rebuild-all-{damage}", "build-db",
                    ["build-db", "--manifest", "{T}/manifest.json", "--rebuild", "--quiet", "--no-checks"],
                    "accept", f"build-db --rebuild on a cache whose every derived array is {what}",
                    {"kinds": list(KINDS), "damage": damage}, {"intact": True}))
    return out


#: hand-made database caches: a valid zip with the right key whose arrays disagree or whose ranges lie
#: outside the frames (exit 70 later in the runtime): refused when opened, built again with one note
DB_CHANGES = {
    "range-stop-past-the-frames": lambda a, m: a.__setitem__("range_stops", a["range_stops"] + 10**6),
    "empty-range": lambda a, m: a.__setitem__("range_stops", a["range_starts"].copy()),
    "parent-after-child": lambda a, m: a["parents"].__setitem__(1, 5),
    "contacts-of-another-length": lambda a, m: a.__setitem__("contacts", a["contacts"][:-3]),
    "rotations-of-three-numbers": lambda a, m: a.__setitem__("rotations", a["rotations"][..., :3]),
    "mirror-map-out-of-range": lambda a, m: a.__setitem__("mirror_map", a["mirror_map"] + 100),
    "one-name-too-few": lambda a, m: m.__setitem__("names", m["names"][:-1]),
    "fps-nan": lambda a, m: m.__setitem__("fps", float("nan")),
    "range-names-missing": lambda a, m: m.pop("range_names"),
    "bone-role-of-no-bone": lambda a, m: m["bone_roles"].__setitem__("hips", "NoSuchBone"),
}


def db_cache_cases() -> list[tuple]:
    """(id, command, argv, expect, what, before spec, after spec) of every hand-made database cache."""
    return [(f"db-cache-run-{change}", "run", _RUN + ["--record", f"{{O}}/db-{change}.bvh"], "note",
             f"run on a hand-made database cache: {change}", {"db_change": change},
             {"same": [[f"{{O}}/db-{change}.bvh", "{O}/reference.bvh"]], "database": True}) for change in DB_CHANGES]


def prepare_derived(T: Path, O: Path, cache: Path) -> None:
    """``T``: a manifest and its take; ``cache``: the database and every derived array (a run), kept
    pristine beside the cache for :func:`before`; ``O``: the reference recording and coverage JSON."""
    T.mkdir(parents=True, exist_ok=True)
    O.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(GOOD / "walk.bvh", T / "walk.bvh")
    shutil.copyfile(GOOD / "manifest.json", T / "manifest.json")
    import json

    m = json.loads((T / "manifest.json").read_text())
    m["clips"] = [{"file": "walk.bvh"}]
    (T / "manifest.json").write_text(json.dumps(m))
    env = {**os.environ, "LMM_STUDIO_CACHE": str(cache), "PYTHONPATH": str(ROOT), "PYTHONDONTWRITEBYTECODE": "1"}
    for argv in ([a.format(T=T, O=O) for a in _RUN] + ["--record", str(O / "reference.bvh")],
                 ["coverage", "--manifest", str(T / "manifest.json"), "--json", str(O / "reference.json")]):
        subprocess.run([sys.executable, "-m", "app.cli", *argv], cwd=ROOT, env=env, check=True,
                       stdout=subprocess.DEVNULL)
    (folder,) = cache.glob("*.derived")
    shutil.rmtree(_pristine(cache), ignore_errors=True)
    shutil.copytree(folder, _pristine(cache))
    (database,) = cache.glob("db-*.npz")
    shutil.copyfile(database, cache.parent / "pristine.npz")
    missing = [k for k in KINDS if not list(folder.glob(f"{k}-*.npy"))]
    if missing:
        raise RuntimeError(f"the run made no derived array of kind {missing}: the kinds list is stale")


def _pristine(cache: Path) -> Path:
    return cache.parent / "pristine.derived"


def _replace(path: Path, data: bytes) -> None:
    """Write ``data`` under a new inode (never into a file some earlier case may still have mapped)."""
    tmp = path.with_name(path.name + ".damage")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _npy_bytes(a) -> bytes:
    import io

    import numpy as np

    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def _damaged(path: Path, damage: str) -> bytes | None:
    """The entry's damaged bytes (None: the damage is to its checksum file)."""
    import numpy as np

    data = path.read_bytes()
    a = np.load(path, allow_pickle=False)
    if damage == "empty":
        return b""
    if damage == "flip":
        b = bytearray(data)
        b[-1 if a.dtype.kind in "iu" else -5] ^= 0x10
        return bytes(b)
    if damage in ("nan", "consistent_nan"):
        b = a.astype(np.result_type(a.dtype, np.float32)).copy()
        b.reshape(-1)[0] = np.nan
        return _npy_bytes(b)
    if damage == "truncated":
        return data[:len(data) // 2]
    if damage in ("wrong_shape", "consistent_wrong_shape"):
        return _npy_bytes(np.zeros((3,) + a.shape[1:], a.dtype))
    if damage == "not_npy":
        return b"not an array\n"
    return None


def _change_database(cache: Path, change: str) -> list[str]:
    """Restore the job's pristine database cache, then write it again with ``change`` made."""
    import numpy as np

    from lmm.data import archive
    from lmm.data.database import Database

    (path,) = cache.glob("db-*.npz")
    shutil.copyfile(cache.parent / "pristine.npz", path)
    arrays, meta = Database.load(path, mmap=False).to_archive()
    arrays = {k: np.array(v) for k, v in arrays.items()}
    DB_CHANGES[change](arrays, meta)
    archive.write(path, arrays, meta, sort_keys=False)
    return []


def before(spec: dict, cache: Path) -> list[str]:
    """Restore the job's pristine derived arrays (and database), then damage those of ``spec['kinds']``
    (or make the database change ``spec['db_change']``). -> problems."""
    from lmm.data.derived import checksum_path, file_crc32

    if "db_change" in spec:
        return _change_database(cache, spec["db_change"])
    (folder,) = cache.glob("*.derived") or [None]
    if folder is None:
        return [f"no derived folder in {cache}"]
    shutil.rmtree(folder)
    shutil.copytree(_pristine(cache), folder)
    damaged = 0
    damage = spec["damage"]
    for kind in spec["kinds"]:
        if (kind, damage) in NOT_A_DAMAGE:
            continue
        for path in folder.glob(f"{kind}-*.npy"):
            data = _damaged(path, damage)
            if data is not None:
                if data == path.read_bytes():
                    return [f"the damage {damage!r} leaves {path.name} as it was"]
                _replace(path, data)
                if damage.startswith("consistent_"):
                    _replace(checksum_path(path), (file_crc32(path) + "\n").encode())
            elif damage == "crc_garbage":
                _replace(checksum_path(path), b"zz\n")
            elif damage == "no_crc":
                checksum_path(path).unlink()
            damaged += 1
    return [] if damaged else [f"no derived array of kinds {spec['kinds']} to damage"]


def after(spec: dict, cache: Path | None, stdout: str = "") -> list[str]:
    """What is wrong with a case's outputs: files that differ from their reference, cached arrays that
    are still damaged or missing, expected files that were not written, words missing from stdout."""
    import glob

    out = []
    if spec.get("stdout_has") and spec["stdout_has"] not in stdout:
        out.append(f"stdout does not name {spec['stdout_has']}: {stdout[:200]!r}")
    for a, b in spec.get("same", []):
        pa, pb = Path(a), Path(b)
        if not pa.is_file():
            out.append(f"{pa.name} was not written")
        elif pa.read_bytes() != pb.read_bytes():
            out.append(f"{pa.name} differs from {pb.name}, made from the intact cache")
    if spec.get("intact") and cache is not None:
        from lmm.data.derived import damage

        folders = list(cache.glob("*.derived"))
        for kind in KINDS:
            entries = [p for f in folders for p in f.glob(f"{kind}-*.npy")]
            if len(entries) != 1:
                out.append(f"{len(entries)} {kind} arrays in the cache afterwards, expected 1")
            out += [f"{p.name} is still damaged afterwards ({why})" for p in entries if (why := damage(p))]
    if spec.get("database") and cache is not None:   # built again: the cache opens, consistent
        from lmm.data.database import Database

        for path in cache.glob("db-*.npz"):
            try:
                Database.load(path, mmap=False)
            except Exception as e:  # noqa: BLE001 - whatever it is, the cache was left bad
                out.append(f"{path.name} does not open afterwards: {type(e).__name__}: {str(e)[:120]}")
    for pattern in spec.get("exists", []):
        if not glob.glob(pattern):
            out.append(f"nothing matches {pattern}")
    return out


# ---- no home folder ----------------------------------------------------------------------------------

#: the environment of a uid without passwd entry and without HOME (the driver also makes pwd.getpwuid
#: raise KeyError): the cache and the config go to $TMPDIR/lmm-studio-home-UID (lmm.data.cache.home_dir)
NO_HOME_UNSET = ("HOME", "LMM_STUDIO_CACHE", "XDG_CACHE_HOME", "LMM_STUDIO_CONFIG", "XDG_CONFIG_HOME")


def no_home_cases() -> list[tuple]:
    """(id, command, argv, what, after spec): ``{H}`` is the fallback home folder."""
    cache = "{H}/.cache/lmm-studio"
    return [
        ("no-home-build-db", "build-db", ["build-db", "--manifest", str(GOOD / "manifest.json"), "--quiet",
                                          "--no-checks", "--jobs", "1"],
         "no passwd entry, HOME unset: build-db (RuntimeError: Could not determine home directory)",
         {"exists": [f"{cache}/db-*.npz"], "stdout_has": cache}),
        ("no-home-run", "run", ["run", "--manifest", str(GOOD / "manifest.json"), "--input", "builtin:circle",
                                "--seconds", "1", "--quiet"],
         "no passwd entry, HOME unset: run", {"exists": [f"{cache}/db-*.npz.derived/features-*.npy"]}),
    ]


def no_home_dir(tmpdir: Path) -> Path:
    return tmpdir / f"lmm-studio-home-{os.getuid()}"


# ---- a studio that cannot open its window -------------------------------------------------------------

DEAD_DISPLAY = ":77"
_STUDIO = ["studio", "--frames", "1", "--no-lmm", "--no-physics", "--no-save-layout"]
_NO_GL = "lmm-studio: error: cannot create an OpenGL context on the display "


def display_cases() -> list[tuple]:
    """(id, display variant, argv, expect, names, field, what, solo): ``dead`` is :data:`DEAD_DISPLAY`;
    ``noglx`` an Xvfb without GLX; ``nodriver`` an Xvfb with GALLIUM_DRIVER naming no driver; ``ok`` a
    working Xvfb, where a studio given a FIFO or a device as a file, or a layout ImGui would crash on,
    goes on without it, saying so in one line (exit 0), or refuses it (exit 1). ``{F}``: a folder holding
    a FIFO ``fifo``. The saved-layout cases (:data:`SAVED_LAYOUTS`) start with that file as the user's
    saved layout."""
    good = ["--manifest", str(GOOD / "manifest.json")]
    given = [(n, _STUDIO + good + ["--layout", str(CORPUS / "layout" / n)]) for n in ("table_columns_2e9.ini",
                                                                                      "table_columns_1e8.ini")]
    return [
        ("studio-layout-given-table-columns-2e9", "ok", given[0][1], "note", ("lmm-studio: ",), given[0][0],
         "--layout with [Table] 2e9 columns (segfault in ImGui)", True),
        ("studio-layout-given-table-columns-1e8", "ok", given[1][1], "note", ("lmm-studio: ",), given[1][0],
         "--layout with [Table] 1e8 columns (3.3 GB, then a negative count saved)", True),
        ("studio-layout-saved-table-columns-negative", "ok", _STUDIO + good, "note", ("lmm-studio: ",), "layout.ini",
         "the user's saved layout.ini holding [Table][0xD4BD52E9,-7936] (every later start crashed or hung)", True),
        ("studio-dead-display", "dead", _STUDIO, "reject", ("{display}",),
         "lmm-studio: error: cannot open the display",
         "DISPLAY=:77, no X server there (glfwSetWindowPos assertion, exit 134)", False),
        ("studio-display-without-glx", "noglx", _STUDIO, "reject", ("{display}",),
         (_NO_GL, "glXChooseFBConfig failed"), "an X server without GLX (abort inside GLFW)", False),
        ("studio-driver-not-loadable", "nodriver", _STUDIO, "reject", ("{display}",),
         (_NO_GL, "cannot create context"), "GALLIUM_DRIVER naming no driver (abort inside GLFW)", False),
        # a studio start each (dearpygui once per process): their own drivers
        ("studio-no-home", "ok", _STUDIO + good, "accept", (), None, "no passwd entry, HOME unset: the studio "
         "(its config and cache in the stated fallback)", True),
        ("studio-zero-offsets", "ok", _STUDIO + ["--manifest", "{F}/zero_offsets.json"], "note", ("lmm-studio: ",),
         "offsets_all_zero.bvh", "a take with every OFFSET 0 (a raw traceback from ik.py, then paused)", True),
        *[(f"studio-input-{name}", "ok", _STUDIO + good + ["--input", f"{{gen}}/input/{name}_1.1m_rows.csv"], "note",
           ("lmm-studio: ",), "lines", f"an input log of 1.1 M rows ended by {sep} (2.1 GB in the studio)", True)
          for name, sep in (("cr_only", "CR alone"), ("u2028", "U+2028"))],
        *[(f"studio-weights-adversarial-{cid}", "ok", ["studio", "--frames", "30", "--no-physics", "--no-save-layout",
                                                       "--input", "builtin:circle", "--weights", "{F}/adversarial.npz"],
           "note", ("lmm-studio: Pose guard: tick",), "the lmm pose",
           f"weights {cid}: their networks give NaN or runaway poses (the LMM root was [null, null, null], no "
           f"message; then a numpy warning line per frame)", True) for cid in ADVERSARIAL_STUDIO.values()],
        ("studio-script-fifo", "ok", _STUDIO + good + ["--script", "{F}/fifo"], "reject", ("fifo",), None,
         "a FIFO as --script (blocked for ever)", True),
        ("studio-script-dev-zero", "ok", _STUDIO + good + ["--script", "/dev/zero"], "reject", ("/dev/zero",), None,
         "/dev/zero as --script", True),
        ("studio-input-fifo", "ok", _STUDIO + good + ["--input", "{F}/fifo"], "note", ("lmm-studio: ",), "fifo",
         "a FIFO as --input (the dialog's FIFO froze the GUI)", True),
        ("studio-layout-fifo", "ok", _STUDIO + good + ["--layout", "{F}/fifo"], "note", ("lmm-studio: ",), "fifo",
         "a FIFO as --layout", True),
        ("studio-weights-fifo", "ok", ["studio", "--frames", "1", "--no-physics", "--no-save-layout", *good,
                                       "--weights", "{F}/fifo"], "note", ("lmm-studio: ",), "fifo",
         "a FIFO as --weights", True),
    ]


#: the shipped networks with absurd weights (special_cases.ADVERSARIAL_WEIGHTS), in the studio: on the
#: shipped database, so these use the suite's own cache (not a private one: a cold build of it is slow)
ADVERSARIAL_STUDIO = {f"studio-weights-adversarial-{cid}": cid for cid in ("stepper-1e4", "stepper-in-std-1e-38",
                                                                           "decompressor-1e4", "projector-1e4")}

#: the cases whose studio opens the shipped database (a fallback, or the networks' own): they use the
#: suite's cache, not a private one (a cold build of the shipped database is slow)
SHARED_CACHE = {"studio-zero-offsets", *ADVERSARIAL_STUDIO}


def prepare_display_case(F: Path, cid: str) -> None:
    """The folder ``F`` of a studio case: a FIFO, the adversarial weights or the manifest it names."""
    import json

    import special_cases

    F.mkdir(parents=True, exist_ok=True)
    os.mkfifo(F / "fifo")
    if cid in ADVERSARIAL_STUDIO:
        special_cases.make_adversarial(F, ADVERSARIAL_STUDIO[cid])
    if cid == "studio-zero-offsets":
        m = json.loads((GOOD / "manifest.json").read_text())
        m["clips"] = [{"file": str(CORPUS / "bvh" / "offsets_all_zero.bvh")}]
        (F / "zero_offsets.json").write_text(json.dumps(m))


#: case -> the layout file the studio finds as the user's saved one (moved aside to layout.ini.bad, with
#: one line, the default layout used)
SAVED_LAYOUTS = {"studio-layout-saved-table-columns-negative": CORPUS / "layout" / "table_columns_negative.ini"}


def _dead_display() -> str | None:
    """:77, or where an X server runs there (other tests start some), the next number without a server's
    socket or lock file; None when 100 numbers are taken."""
    for n in range(int(DEAD_DISPLAY[1:]), int(DEAD_DISPLAY[1:]) + 100):
        if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists():
            return f":{n}"
    return None


def start_displays() -> tuple[dict, list]:
    """{variant: display or None} and the Xvfb processes to stop (``dead``: see :func:`_dead_display`)."""
    displays = {"dead": _dead_display(), "noglx": None, "nodriver": None, "ok": None}
    procs = []
    exe = shutil.which("Xvfb")
    if exe is None:
        return displays, procs
    for variant, extra in (("noglx", ["-extension", "GLX"]), ("nodriver", []), ("ok", [])):
        read_fd, write_fd = os.pipe()
        # -noreset: the server does not reset as its last client leaves (a start in that moment found no display)
        proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", "800x600x24", "-nolisten", "tcp",
                                 "-noreset", *extra], pass_fds=(write_fd,), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        os.close(write_fd)
        procs.append(proc)
        with os.fdopen(read_fd) as f:
            number = f.readline().strip()
        if number.isdigit():
            displays[variant] = f":{number}"
    return displays, procs


def display_env(variant: str, display: str) -> dict:
    env = {"DISPLAY": display, "WAYLAND_DISPLAY": None}
    if variant == "nodriver":
        env.update(LIBGL_ALWAYS_SOFTWARE="1", GALLIUM_DRIVER="nonexistent")
    return env
