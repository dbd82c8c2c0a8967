"""The database cache: its key, its file's name and its folder.

A built database is cached in one file keyed by a hash of everything the build reads (file contents and
settings, :func:`manifest_key`); the file's name is made of that hash only (never of text from the
manifest), and it is reused only while the build code is unchanged (:func:`build_code_fingerprint`).
:func:`lmm.data.build.load_or_build` reads or writes it.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from lmm.data.database import DB_FORMAT_VERSION
from lmm.data.derived import file_digest as _file_digest
from lmm.data.manifest import Manifest, ManifestError


def build_code_fingerprint() -> str:
    """Hash of the source of every module the build runs.

    A cache file is reused only when this matches, so a change to the build code can never serve a stale
    cache under an unchanged key (the key itself changes only with DB_FORMAT_VERSION, because networks
    trained on a database are tied to it: bump the version when a change alters the built data).
    """
    h = hashlib.sha256()
    data = Path(__file__).resolve().parent
    engine = data.parent
    for path in (data / "database.py", data / "build.py", data / "preparation.py", engine / "filters.py",
                 engine / "quat.py", engine / "kinematics.py", data / "bvh.py", data / "manifest.py"):
        h.update(path.read_bytes())
    return h.hexdigest()

def manifest_key(manifest: Manifest) -> str:
    """Hash of everything the build reads: file contents, settings and the build code's version.

    Tags are not part of it: they change no frame, so retagging keeps trained networks valid (a cached
    database whose tags differ from the manifest's is retagged on load)."""
    h = hashlib.sha256()
    h.update(f"lmm-db-v{DB_FORMAT_VERSION}".encode())
    h.update(json.dumps(manifest.settings(), sort_keys=True).encode())
    for ci, clip in enumerate(manifest.clips):
        try:
            h.update(_file_digest(clip.file).encode())
        except OSError as e:
            raise ManifestError(manifest.path, f"clips[{ci}].file",
                                f"cannot read {clip.file}: {e.strerror or type(e).__name__}") from None
    return h.hexdigest()


def cache_file_name(key: str) -> str:
    """The cache file of a database: its key only (hex digits), never text from the manifest."""
    if not key or any(c not in "0123456789abcdef" for c in key):
        raise ValueError(f"a database key is hex digits, got {key[:20]!r}")
    return f"db-{key[:32]}.npz"


def home_dir() -> Path:
    """The user's home folder; where there is none (``HOME`` unset and no passwd entry for the uid, as in
    some containers) ``lmm-studio-home-UID`` in the system's temporary folder, so the cache and the
    studio's config still have a place (the README names it)."""
    try:
        return Path.home()
    except RuntimeError:
        import tempfile

        return Path(tempfile.gettempdir()) / f"lmm-studio-home-{os.getuid() if hasattr(os, 'getuid') else 0}"


def default_cache_dir() -> Path:
    env = os.environ.get("LMM_STUDIO_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or (home_dir() / ".cache")
    return Path(base) / "lmm-studio"
