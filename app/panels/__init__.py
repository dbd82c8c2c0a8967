"""The studio's panels: one module per dockable window (dearpygui lives only in app/)."""
