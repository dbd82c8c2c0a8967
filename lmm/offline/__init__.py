"""Offline work on the learned networks: torch models and training, evaluation and ONNX export.
The runtime never imports this package."""
