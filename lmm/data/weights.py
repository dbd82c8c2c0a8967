"""Network weight files: a pickle-free ``.npz`` with a JSON metadata record.

Layout of a file:

* ``{network}.W{i}`` (in x out), ``{network}.b{i}``, ``{network}.in_mean``, ``{network}.in_std``,
  ``{network}.out_mean``, ``{network}.out_std``: float32 arrays per network
  (see :meth:`lmm.offline.networks.NormalizedMLP.to_arrays`);
* ``metadata``: UTF-8 JSON as a uint8 array: format version, network sizes and activations, the
  feature layout, the database key, the feature normalisation the networks were trained in, the
  skeleton, latent statistics and the training settings.

:func:`load` checks everything and raises :class:`WeightsError` naming the file and the problem:
truncated or corrupt file, missing arrays, wrong shapes, NaN/inf weights, a different database,
a different feature layout.
"""
from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.data.atomic import atomic_write
from lmm.errors import InputError

WEIGHTS_FORMAT_VERSION = 1
PARTS = ("in_mean", "in_std", "out_mean", "out_std")


class WeightsError(InputError):
    """A weights file that cannot be used; the message names the file and the problem."""


@dataclass
class WeightsFile:
    path: Path
    arrays: dict[str, np.ndarray]
    metadata: dict

    @property
    def networks(self) -> list[str]:
        return list(self.metadata.get("networks", {}))

    def spec(self, name: str) -> dict:
        return self.metadata["networks"][name]

    def network_arrays(self, name: str) -> dict[str, np.ndarray]:
        return {k: v for k, v in self.arrays.items() if k.startswith(name + ".")}

    def nbytes(self, names=None) -> int:
        names = self.networks if names is None else names
        return int(sum(v.nbytes for n in names for v in self.network_arrays(n).values()))


def layout_signature(layout_dicts: list[dict]) -> list[dict]:
    """The part of a feature layout that changes what a feature vector means (weights only rescale)."""
    return [{k: v for k, v in d.items() if k != "weight"} for d in layout_dicts]


def expected_shapes(name: str, spec: dict) -> dict[str, tuple[int, ...]]:
    sizes = [int(spec["n_in"]), *[int(h) for h in spec["hidden"]], int(spec["n_out"])]
    out = {}
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        out[f"{name}.W{i}"] = (a, b)
        out[f"{name}.b{i}"] = (b,)
    out[f"{name}.in_mean"] = out[f"{name}.in_std"] = (sizes[0],)
    out[f"{name}.out_mean"] = out[f"{name}.out_std"] = (sizes[-1],)
    return out


def save(path, arrays: dict[str, np.ndarray], metadata: dict) -> Path:
    """Write arrays + metadata atomically (a killed run never leaves a half-written file at ``path``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = dict(metadata)
    meta["format_version"] = WEIGHTS_FORMAT_VERSION
    for name, spec in meta.get("networks", {}).items():
        for key, shape in expected_shapes(name, spec).items():
            if key not in arrays or tuple(arrays[key].shape) != shape:
                raise WeightsError(f"{path}: refusing to save: {key} is missing or not {shape}")
    out = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in arrays.items()}
    out["metadata"] = np.frombuffer(json.dumps(meta, sort_keys=True).encode("utf-8"), dtype=np.uint8)
    with atomic_write(path) as f:
        np.savez(f, **out)
    return path


def load(path, require=None, db_key: str | None = None, layout_dicts: list[dict] | None = None) -> WeightsFile:
    """Load and validate a weights file.

    require: network names that must be present (default: all named in the metadata).
    db_key: when given, must equal the key the networks were trained on.
    layout_dicts: when given (``features.layout_dicts()``), must describe the same feature layout.
    """
    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: weights file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            names = list(z.files)
            if "metadata" not in names:
                raise WeightsError(f"{path}: not an lmm-studio weights file (no metadata record)")
            arrays = {k: z[k] for k in names}
    except WeightsError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, zipfile.LargeZipFile) as e:
        raise WeightsError(f"{path}: truncated or corrupt weights file ({type(e).__name__}: {e})") from None
    except Exception as e:  # zlib.error and friends from a damaged member
        raise WeightsError(f"{path}: truncated or corrupt weights file ({type(e).__name__}: {e})") from None
    try:
        metadata = json.loads(arrays.pop("metadata").tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError) as e:
        raise WeightsError(f"{path}: metadata record is not valid JSON ({e})") from None
    if metadata.get("format_version") != WEIGHTS_FORMAT_VERSION:
        raise WeightsError(f"{path}: weights format {metadata.get('format_version')!r}, expected {WEIGHTS_FORMAT_VERSION}")
    nets = metadata.get("networks")
    if not isinstance(nets, dict) or not nets:
        raise WeightsError(f"{path}: metadata lists no networks")
    require = list(nets) if require is None else list(require)
    for name in require:
        if name not in nets:
            raise WeightsError(f"{path}: no {name} network in this file (it holds: {', '.join(nets)})")
    for name in nets:
        for key, shape in expected_shapes(name, nets[name]).items():
            if key not in arrays:
                raise WeightsError(f"{path}: missing array {key}")
            a = arrays[key]
            if tuple(a.shape) != shape:
                raise WeightsError(f"{path}: {key} has shape {tuple(a.shape)}, expected {shape} "
                                   f"(from the {name} sizes in the metadata)")
            if a.dtype.kind != "f":
                raise WeightsError(f"{path}: {key} has dtype {a.dtype}, expected float32")
            if not np.all(np.isfinite(a)):
                bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
                raise WeightsError(f"{path}: {key} holds {bad} NaN/inf values")
        if np.any(arrays[f"{name}.in_std"] <= 0):
            raise WeightsError(f"{path}: {name}.in_std has non-positive entries")
    fix = ("open the data they were trained on (--manifest), or retrain on this data: "
           "`lmm-studio train all --manifest YOUR_MANIFEST --out DIR`, then --weights DIR/default.npz")
    if db_key is not None and metadata.get("database_key") != db_key:
        trained = (f"'{metadata.get('database_name', '?')}', {metadata.get('n_frames', '?')} frames, "
                   f"key {str(metadata.get('database_key'))[:16]}")
        raise WeightsError(f"{path}: trained on another database ({trained}; the loaded database has key "
                           f"{db_key[:16]}): {fix}")
    if layout_dicts is not None:
        theirs = metadata.get("feature_layout", [])
        if layout_signature(theirs) != layout_signature(layout_dicts):
            from lmm.features import describe_schema_difference

            raise WeightsError(f"{path}: trained on another feature schema ("
                               f"{describe_schema_difference(theirs, layout_dicts)}): {fix}")
    for key in ("feature_mean", "feature_inv_scale"):
        v = np.asarray(metadata.get(key, []), dtype=np.float64)
        if "decompressor" in nets and v.shape != (int(nets["decompressor"]["n_in"]) - int(metadata.get("latent", 0)),):
            raise WeightsError(f"{path}: metadata {key} has {v.size} entries, does not match the networks")
        if not np.all(np.isfinite(v)):
            raise WeightsError(f"{path}: metadata {key} holds NaN/inf values")
    return WeightsFile(path, arrays, metadata)
