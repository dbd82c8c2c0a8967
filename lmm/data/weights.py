"""Network weight files: an archive of arrays + JSON metadata (:mod:`lmm.data.archive`).

Layout of a file:

* ``{network}.W{i}`` (in x out), ``{network}.b{i}``, ``{network}.in_mean``, ``{network}.in_std``,
  ``{network}.out_mean``, ``{network}.out_std``: float32 arrays per network
  (see :meth:`lmm.offline.networks.NormalizedMLP.to_arrays`);
* ``metadata``: UTF-8 JSON as a uint8 array: format version, network sizes and activations, the
  feature layout, the database key, the feature normalisation the networks were trained in, the
  skeleton, latent statistics and the training settings.

:func:`load` checks everything and raises :class:`WeightsError` naming the file and the problem (the
metadata field or the array): truncated or corrupt file, missing or malformed metadata fields, missing
arrays, wrong shapes, NaN/inf or absurd weights, a zero normalisation, a different database, a different
feature layout. Costs are checked before the work: only the arrays the metadata names are read, each
after its declared size is checked against its expected shape (an extra or oversized member costs
nothing), and the metadata record has a size and nesting limit.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.data import archive
from lmm.errors import InputError

WEIGHTS_FORMAT_VERSION = 1
PARTS = ("in_mean", "in_std", "out_mean", "out_std")

#: Widest layer accepted (units; also n_in/n_out): the shipped networks are 512 wide and read 27 to 668
#: features; 4096 leaves room for 8x wider ones (a 4096 x 4096 float32 layer is 64 MB).
MAX_UNITS = 4096
#: Most hidden layers per network: the shipped projector has 4.
MAX_HIDDEN_LAYERS = 8
#: Most networks in one file: a file holds the 3 runtime networks or the compressor.
MAX_NETWORKS = 8
#: Most bones: the shipped skeleton has 23; a pose vector grows ~15 floats per bone.
MAX_BONES = 1024
#: Largest |value| of any weight, bias or normalisation entry. Trained files stay under 15 (the shipped
#: ones: weights <= 2.3, out_std <= 13.3); with inputs normalised to ~10, a layer of at most 4096 units
#: of |w| <= 1e4 multiplies magnitudes by <= 4e7, so 4 layers stay below float32's 3.4e38 instead of
#: overflowing to inf (a weight of 3e38 overflowed in the first tick and broke the run).
MAX_WEIGHT_MAGNITUDE = 1e4
#: Largest |feature_mean| and feature_inv_scale: raw features are in metres, m/s and unit vectors
#: (the shipped means <= 3, inv scales 0.98..4.7).
MAX_FEATURE_MAGNITUDE = 1e6
#: Largest metadata record (bytes): the shipped one is ~5 KB (layout, bone names, recipe).
MAX_METADATA_BYTES = 1024 * 1024


class WeightsError(InputError):
    """A weights file that cannot be used; the message names the file and the problem."""


def _int_field(path, meta: dict, key: str, lo: int, hi: int, where: str = "metadata field") -> int:
    value = meta.get(key) if isinstance(meta, dict) else None
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        shown = "missing" if value is None else repr(value)[:40]
        raise WeightsError(f"{path}: {where} {key!r}: expected an integer in [{lo}, {hi}], got {shown}")
    return value


def _vector_field(path, meta: dict, key: str, n: int | None, lo: float, hi: float) -> np.ndarray:
    """A metadata list of ``n`` numbers (any length if None), each finite and in [lo, hi]."""
    value = meta.get(key)
    if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                              for v in value):
        shown = "missing" if value is None else f"a {type(value).__name__}" if not isinstance(value, list) \
            else "a list holding a non-number"
        raise WeightsError(f"{path}: metadata field {key!r}: expected a list of numbers, got {shown}")
    if n is not None and len(value) != n:
        raise WeightsError(f"{path}: metadata field {key!r} has {len(value)} entries, does not match the "
                           f"networks ({n} features)")
    try:
        v = np.asarray(value, dtype=np.float64)
    except OverflowError:
        raise WeightsError(f"{path}: metadata field {key!r}: a number beyond float range") from None
    if not np.all(np.isfinite(v)):
        raise WeightsError(f"{path}: metadata field {key!r} holds NaN/inf values")
    bad = np.flatnonzero((v < lo) | (v > hi))
    if bad.size:
        raise WeightsError(f"{path}: metadata field {key!r}: entry {int(bad[0])} is {float(v[bad[0]]):g}, "
                           f"outside [{lo:g}, {hi:g}]")
    return v


def check_network_spec(path, name, spec) -> None:
    """``networks[name]``: sizes within the limits, a known activation; WeightsError naming the field."""
    where = f"metadata field 'networks.{name}'"
    if not isinstance(name, str) or not isinstance(spec, dict):
        raise WeightsError(f"{path}: {where}: expected an object with n_in, hidden, n_out, activation")
    _int_field(path, spec, "n_in", 1, MAX_UNITS, where)
    _int_field(path, spec, "n_out", 1, MAX_UNITS, where)
    hidden = spec.get("hidden")
    if not isinstance(hidden, list) or len(hidden) > MAX_HIDDEN_LAYERS or not all(
            isinstance(h, int) and not isinstance(h, bool) and 1 <= h <= MAX_UNITS for h in hidden):
        raise WeightsError(f"{path}: {where} 'hidden': expected a list of at most {MAX_HIDDEN_LAYERS} layer "
                           f"sizes in [1, {MAX_UNITS}], got {repr(hidden)[:40]}")
    if spec.get("activation") not in ("relu", "elu"):
        raise WeightsError(f"{path}: {where} 'activation': expected 'relu' or 'elu', "
                           f"got {repr(spec.get('activation'))[:40]}")
    skip = spec.get("skip", False)
    if not isinstance(skip, bool) or (skip and spec["n_out"] < spec["n_in"]):
        raise WeightsError(f"{path}: {where} 'skip': expected false, or true with n_out >= n_in")


def check_metadata(path, meta) -> None:
    """Every metadata field the program reads, checked for presence, type and range (one line per
    problem naming the field). The runtime file (with a decompressor) must also say its feature
    normalisation, latent size and bone count."""
    if not isinstance(meta, dict):
        raise WeightsError(f"{path}: metadata record is not a JSON object")
    if meta.get("format_version") != WEIGHTS_FORMAT_VERSION:
        raise WeightsError(f"{path}: weights format {repr(meta.get('format_version'))[:40]}, "
                           f"expected {WEIGHTS_FORMAT_VERSION}")
    nets = meta.get("networks")
    if not isinstance(nets, dict) or not nets:
        raise WeightsError(f"{path}: metadata lists no networks")
    if len(nets) > MAX_NETWORKS:
        raise WeightsError(f"{path}: metadata field 'networks': {len(nets)} networks, more than {MAX_NETWORKS}")
    for name, spec in nets.items():
        check_network_spec(path, name, spec)
    runtime = "decompressor" in nets
    if runtime or "latent" in meta:
        latent = _int_field(path, meta, "latent", 0, MAX_UNITS)
    if runtime or "n_bones" in meta:
        _int_field(path, meta, "n_bones", 1, MAX_BONES)
    if "n_frames" in meta:
        _int_field(path, meta, "n_frames", 0, 2 ** 40)
    n_features = int(nets["decompressor"]["n_in"]) - latent if runtime else None
    if runtime and n_features < 1:
        raise WeightsError(f"{path}: metadata field 'latent': {latent} leaves no features in the decompressor's "
                           f"{nets['decompressor']['n_in']} inputs")
    for key, lo in (("feature_mean", -MAX_FEATURE_MAGNITUDE), ("feature_inv_scale", 0.0)):
        if runtime or key in meta:
            v = _vector_field(path, meta, key, n_features, lo, MAX_FEATURE_MAGNITUDE)
            if key == "feature_inv_scale" and np.any(v <= 0.0):
                raise WeightsError(f"{path}: metadata field 'feature_inv_scale': entry {int(np.argmax(v <= 0))} "
                                   f"is 0 (every feature's scale must be positive)")
    for key in ("feature_layout", "bone_names", "parents"):
        if key in meta and not isinstance(meta[key], list):
            raise WeightsError(f"{path}: metadata field {key!r}: expected a list, got {type(meta[key]).__name__}")
    if "feature_layout" in meta and not all(isinstance(d, dict) for d in meta["feature_layout"]):
        raise WeightsError(f"{path}: metadata field 'feature_layout': expected a list of channel objects")
    recipe = meta.get("recipe", {})
    if not isinstance(recipe, dict) or not isinstance(recipe.get("projector_noise", 1.0), (int, float)):
        raise WeightsError(f"{path}: metadata field 'recipe': expected an object (projector_noise a number)")


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
    """Write arrays + metadata as an archive (:mod:`lmm.data.archive`, atomic)."""
    path = Path(path)
    meta = dict(metadata)
    meta["format_version"] = WEIGHTS_FORMAT_VERSION
    for name, spec in meta.get("networks", {}).items():
        for key, shape in expected_shapes(name, spec).items():
            if key not in arrays or tuple(arrays[key].shape) != shape:
                raise WeightsError(f"{path}: refusing to save: {key} is missing or not {shape}")
    return archive.write(path, {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in arrays.items()}, meta)


def load(path, require=None, db_key: str | None = None, layout_dicts: list[dict] | None = None) -> WeightsFile:
    """Load and validate a weights file.

    require: network names that must be present (default: all named in the metadata).
    db_key: when given, must equal the key the networks were trained on.
    layout_dicts: when given (``features.layout_dicts()``), must describe the same feature layout.
    """
    path = Path(path)
    if not path.is_file():
        from lmm.data.reading import not_regular

        raise WeightsError(f"{path}: {not_regular(path, 'weights file')}")
    with archive.read(path, WeightsError, "weights file") as r:
        metadata = r.metadata(MAX_METADATA_BYTES)
        check_metadata(path, metadata)
        nets = metadata["networks"]
        require = list(nets) if require is None else list(require)
        for name in require:
            if name not in nets:
                raise WeightsError(f"{path}: no {name} network in this file (it holds: {', '.join(nets)})")
        shapes = {k: v for name in nets for k, v in expected_shapes(name, nets[name]).items()}
        r.refuse_unknown(shapes, f"a weights file holds only 'metadata' and the arrays of its networks: "
                                 f"{', '.join(nets)}")
        arrays = r.float_arrays(shapes, MAX_WEIGHT_MAGNITUDE)
    for name in nets:
        for part in ("in_std", "out_std"):
            if np.any(arrays[f"{name}.{part}"] <= 0):
                raise WeightsError(f"{path}: {name}.{part} has non-positive entries (a normalisation "
                                   f"scale must be positive)")
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
            from lmm.data.feature_schema import describe_schema_difference

            raise WeightsError(f"{path}: trained on another feature schema ("
                               f"{describe_schema_difference(theirs, layout_dicts)}): {fix}")
    return WeightsFile(path, arrays, metadata)
