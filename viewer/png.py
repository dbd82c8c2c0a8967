"""PNG output for screenshots: written whole or not at all.

The image is encoded in memory, written to a hidden temporary file beside the target and renamed over
it, so a full disk or a crash never leaves half a PNG under the target's name; an unwritable target
raises ``OSError`` naming it (checked by :func:`check_writable` before any rendering, too).
"""
from __future__ import annotations

import io
import os
import secrets
from pathlib import Path

import numpy as np


def check_writable(path) -> Path:
    """Raise ``OSError`` (naming ``path``) unless a file can be created at ``path``: its folder is
    created if needed and must accept a new file; ``path`` must not be a folder."""
    out = Path(path)
    if out.is_dir():
        raise IsADirectoryError(21, "is a folder, not a file", str(out))
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        probe = out.with_name(f".{out.name}.{os.getpid()}.{secrets.token_hex(4)}.probe")
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except OSError as e:
        raise OSError(e.errno, f"cannot write here ({e.strerror})", str(out)) from None
    os.close(fd)
    os.unlink(probe)
    return out


def save_png(path, image: np.ndarray) -> Path:
    """Save an ``(H, W, 3|4)`` uint8 image as PNG at ``path`` atomically (see the module doc)."""
    from PIL import Image

    out = Path(path)
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "xb") as f:
            f.write(buf.getbuffer())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, out)
    except OSError as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise OSError(e.errno, f"cannot write the image ({e.strerror})", str(out)) from None
    return out
