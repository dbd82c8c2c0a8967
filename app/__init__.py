"""lmm-studio application layer: the dearpygui studio and the ``lmm-studio`` command."""
