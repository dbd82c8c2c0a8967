"""ONNX export of the runtime networks, written directly from the numpy weights with ``onnx.helper``.

Each network becomes one small graph, input ``x`` (batch, n_in) float32, output ``y`` (batch, n_out):
``Sub(in_mean) -> Div(in_std) -> [Gemm -> Relu|Elu] x hidden -> Gemm -> Mul(out_std) -> Add(out_mean)``,
the same function as :class:`lmm.nn.MLP` and :class:`lmm.offline.networks.NormalizedMLP`; a network with a skip
connection (the projector) adds ``MatMul(x, [I 0])`` to ``y``. No torch needed.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

OPSET = 17


def mlp_to_onnx(mlp, name: str, metadata: dict | None = None):
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    inits = [numpy_helper.from_array(mlp.in_mean.astype(np.float32), f"{name}_in_mean"),
             numpy_helper.from_array((1.0 / mlp.in_inv_std).astype(np.float32), f"{name}_in_std"),
             numpy_helper.from_array(mlp.out_mean.astype(np.float32), f"{name}_out_mean"),
             numpy_helper.from_array(mlp.out_std.astype(np.float32), f"{name}_out_std")]
    nodes = [helper.make_node("Sub", ["x", f"{name}_in_mean"], ["centred"]),
             helper.make_node("Div", ["centred", f"{name}_in_std"], ["h0"])]
    h = "h0"
    last = len(mlp.weights) - 1
    for i, (w, b) in enumerate(zip(mlp.weights, mlp.biases)):
        inits += [numpy_helper.from_array(w.astype(np.float32), f"{name}_W{i}"),
                  numpy_helper.from_array(b.astype(np.float32), f"{name}_b{i}")]
        lin = f"linear{i}"
        nodes.append(helper.make_node("Gemm", [h, f"{name}_W{i}", f"{name}_b{i}"], [lin]))
        if i < last:
            act = "Relu" if mlp.activation == "relu" else "Elu"
            kwargs = {"alpha": 1.0} if act == "Elu" else {}
            nodes.append(helper.make_node(act, [lin], [f"h{i + 1}"], **kwargs))
            h = f"h{i + 1}"
        else:
            h = lin
    nodes += [helper.make_node("Mul", [h, f"{name}_out_std"], ["scaled"]),
              helper.make_node("Add", ["scaled", f"{name}_out_mean"], ["y_mlp" if mlp.skip else "y"])]
    if mlp.skip:  # y[:, :n_in] += x, as a matmul with a constant [I 0] so engines need no slicing ops
        pad = np.zeros((mlp.n_in, mlp.n_out), np.float32)
        pad[np.arange(mlp.n_in), np.arange(mlp.n_in)] = 1.0
        inits.append(numpy_helper.from_array(pad, f"{name}_skip"))
        nodes += [helper.make_node("MatMul", ["x", f"{name}_skip"], ["skipped"]),
                  helper.make_node("Add", ["y_mlp", "skipped"], ["y"])]
    graph = helper.make_graph(
        nodes, f"lmm_{name}",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["batch", mlp.n_in])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["batch", mlp.n_out])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="lmm-studio")
    model.ir_version = 8
    for k, v in (metadata or {}).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v if isinstance(v, str) else json.dumps(v)
    onnx.checker.check_model(model)
    return model


def export_networks(nets, out_dir) -> list[Path]:
    """Write decompressor.onnx, stepper.onnx and projector.onnx for an :class:`lmm.learned.LMMNetworks`
    as one set: each model goes to a temporary beside its name, and only when all three are on disk are
    they renamed over the old files, so a full disk or a write error never leaves a mix of an old and a
    new export (the temporaries are removed, the old set stays; ``OSError`` names the file)."""
    from contextlib import ExitStack

    from lmm.data.atomic import atomic_write, check_writable

    out_dir = Path(out_dir)
    check_writable(out_dir / "decompressor.onnx")  # before building any model
    meta = {k: nets.metadata.get(k) for k in ("database_key", "feature_layout", "feature_mean",
                                              "feature_inv_scale", "latent", "bone_names", "pose_vector_size")}
    meta["dt_s"] = 1.0 / 60.0
    models = {out_dir / f"{name}.onnx": mlp_to_onnx(getattr(nets, name), name, meta).SerializeToString()
              for name in ("decompressor", "stepper", "projector")}   # what onnx.save writes, no external data
    with ExitStack() as renames:   # leaving it renames every temporary, or (on an error) removes them all
        for path, data in models.items():
            f = renames.enter_context(atomic_write(path, "wb"))
            f.write(data)
            f.flush()
            os.fsync(f.fileno())   # a full disk fails here, before any file is renamed
    return list(models)
