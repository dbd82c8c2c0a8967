"""The four Learned Motion Matching networks as torch modules (training and export only).

Every network is a plain MLP wrapped with fixed input/output normalisation buffers, so the
function a runtime has to reproduce is always

    y = out_mean + out_std * mlp((x - in_mean) / in_std)   (+ x on the first n_in outputs with ``skip``)

and the numpy runtime (:mod:`lmm.nn`) and the ONNX export read the same arrays.

============  =============================================  ==========
network       layout (defaults)                               activation
============  =============================================  ==========
compressor    668 -> 512 -> 512 -> 512 -> 32 (training only)  ELU
decompressor  59 (27 features + 32 latent) -> 512 -> 338      ReLU
stepper       59 -> 512 -> 512 -> 59 (time derivative)        ReLU
projector     27 -> 512 x4 -> 59, skip (features += query)      ReLU
============  =============================================  ==========

The projector's ``skip`` is our one deviation from the paper's layout (measured reason in
:mod:`lmm.offline.training`): its first 27 outputs are the query plus a learned correction, so the network
learns how far to move a query onto the database rather than re-creating the query from scratch.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

ACTIVATIONS = ("relu", "elu")


@dataclass(frozen=True)
class MLPSpec:
    """Sizes of one MLP: ``n_in -> hidden[0] -> ... -> n_out``."""
    n_in: int
    hidden: tuple[int, ...]
    n_out: int
    activation: str = "relu"
    skip: bool = False   # add the input to the first n_in outputs (needs n_out >= n_in)

    def __post_init__(self):
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {self.activation!r} (expected one of {ACTIVATIONS})")
        if self.skip and self.n_out < self.n_in:
            raise ValueError(f"a skip connection needs n_out >= n_in (got {self.n_in} -> {self.n_out})")

    @property
    def sizes(self) -> list[int]:
        return [self.n_in, *self.hidden, self.n_out]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "MLPSpec":
        return cls(int(d["n_in"]), tuple(int(h) for h in d["hidden"]), int(d["n_out"]), str(d.get("activation", "relu")),
                   bool(d.get("skip", False)))


def default_specs(n_features: int = 27, n_latent: int = 32, n_pose: int = 338, n_compressor_in: int = 668,
                  hidden: int = 512, projector_skip: bool = True) -> dict[str, MLPSpec]:
    """The paper's layouts (Table 1) for a given feature / latent / pose size (projector with a skip)."""
    state = n_features + n_latent
    return {
        "compressor": MLPSpec(n_compressor_in, (hidden, hidden, hidden), n_latent, "elu"),
        "decompressor": MLPSpec(state, (hidden,), n_pose, "relu"),
        "stepper": MLPSpec(state, (hidden, hidden), state, "relu"),
        "projector": MLPSpec(n_features, (hidden, hidden, hidden, hidden), state, "relu", projector_skip),
    }


class NormalizedMLP(nn.Module):
    """An MLP between fixed input and output normalisations (buffers, saved with the weights)."""

    def __init__(self, spec: MLPSpec):
        super().__init__()
        self.spec = spec
        sizes = spec.sizes
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))
        self.act = nn.ELU() if spec.activation == "elu" else nn.ReLU()
        self.register_buffer("in_mean", torch.zeros(spec.n_in))
        self.register_buffer("in_std", torch.ones(spec.n_in))
        self.register_buffer("out_mean", torch.zeros(spec.n_out))
        self.register_buffer("out_std", torch.ones(spec.n_out))

    def set_normalization(self, in_mean=None, in_std=None, out_mean=None, out_std=None) -> None:
        for name, value in (("in_mean", in_mean), ("in_std", in_std), ("out_mean", out_mean), ("out_std", out_std)):
            if value is not None:
                getattr(self, name).copy_(torch.as_tensor(value, dtype=torch.float32))

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """The MLP alone, on normalised input, giving normalised output."""
        for layer in self.layers[:-1]:
            x = self.act(layer(x))
        return self.layers[-1](x)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.out_mean + self.out_std * self.raw((x - self.in_mean) / self.in_std)
        if self.spec.skip:
            y = torch.cat([y[..., :self.spec.n_in] + x, y[..., self.spec.n_in:]], dim=-1)
        return y

    def parameter_count(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def to_arrays(self, prefix: str) -> dict:
        """Weights as float32 numpy arrays named ``{prefix}.W{i}`` (in x out), ``{prefix}.b{i}`` and the
        normalisation vectors; the layout :mod:`lmm.nn` and :mod:`lmm.data.weights` read."""
        out = {}
        for i, layer in enumerate(self.layers):
            out[f"{prefix}.W{i}"] = layer.weight.detach().cpu().numpy().T.copy()
            out[f"{prefix}.b{i}"] = layer.bias.detach().cpu().numpy().copy()
        for name in ("in_mean", "in_std", "out_mean", "out_std"):
            out[f"{prefix}.{name}"] = getattr(self, name).detach().cpu().numpy().copy()
        return out

    def load_arrays(self, arrays: dict, prefix: str) -> None:
        with torch.no_grad():
            for i, layer in enumerate(self.layers):
                layer.weight.copy_(torch.as_tensor(arrays[f"{prefix}.W{i}"]).T)
                layer.bias.copy_(torch.as_tensor(arrays[f"{prefix}.b{i}"]))
            self.set_normalization(arrays[f"{prefix}.in_mean"], arrays[f"{prefix}.in_std"],
                                   arrays[f"{prefix}.out_mean"], arrays[f"{prefix}.out_std"])


def build(specs: dict[str, MLPSpec]) -> dict[str, NormalizedMLP]:
    return {name: NormalizedMLP(spec) for name, spec in specs.items()}
