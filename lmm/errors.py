"""The one base class of every expected error: a bad file, field or command-line argument.

Each module raises its own subclass (``BVHError``, ``ManifestError``, ``WeightsError``, ``TuningError``,
the input log's ``InputLogError``...), whose ``str()`` is the ONE line shown to the user: it names the
file (its path, never its contents) and the line or field. ``app/cli.py`` turns any of them into
``lmm-studio COMMAND: error: <line>`` and exit code 1; anything else is a bug and is reported as an
internal error with the trace written to a file.
"""


class InputError(ValueError):
    """A bad file, field or argument; str(e) is the one line shown to the user (names file and field)."""
