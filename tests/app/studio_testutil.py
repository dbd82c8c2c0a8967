"""Paths shared by the studio tests (imported by name: pytest puts this folder on sys.path)."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT / "tests" / "bvh_corpus"


class RealKeyStudio:
    """The real studio in a subprocess on an Xvfb display, driven by real key and mouse events (xdotool).

    ``with RealKeyStudio(tmp_path, display, cache, actions=[...], args=[...]) as s:`` starts it and finds
    its window (``s.win``); ``s.xdo(...)`` runs xdotool on that display. Leaving the block asks the studio
    to quit (its script watches a stop file), waits, and kills it if it hangs; ``s.returncode``,
    ``s.stderr`` and ``s.dump()`` (the state dump) are then available."""

    def __init__(self, tmp_path, display, cache, actions=(), args=()):
        import json

        self.tmp = Path(tmp_path)
        self.stop = self.tmp / "stop"
        (self.tmp / "script.json").write_text(json.dumps({"actions": [
            {"frame": 0, "do": "quit_when_exists", "path": str(self.stop)}, *actions]}))
        self.env = dict(__import__("os").environ, DISPLAY=display, LMM_STUDIO_CONFIG=str(self.tmp / "cfg"),
                        LMM_STUDIO_CACHE=str(cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0")
        self.args = ["--no-lmm", "--no-gamepads", *args, "--script", str(self.tmp / "script.json"),
                     "--dump-state", str(self.tmp / "dump.json")]
        self.proc = None
        self.win = None
        self.returncode = None
        self.stderr = ""

    def xdo(self, *args, timeout=30):
        import subprocess

        return subprocess.run(["xdotool", *args], env=self.env, capture_output=True, text=True, timeout=timeout)

    def __enter__(self):
        import subprocess
        import sys

        self.proc = subprocess.Popen([sys.executable, "-m", "app.cli", *self.args], cwd=self.tmp, env=self.env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            found = self.xdo("search", "--sync", "--onlyvisible", "--name", "lmm-studio", timeout=90)
            assert found.returncode == 0 and found.stdout.split(), found.stderr
            self.win = found.stdout.split()[0]
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc):
        self.stop.write_text("")
        try:
            _, self.stderr = self.proc.communicate(timeout=60)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                _, self.stderr = self.proc.communicate()
        self.returncode = self.proc.returncode
        return False

    def rect(self, path, item: str, wait_s: float = 60.0, settle_s: float = 0.5) -> list[float]:
        """The screen rectangle [x0, y0, x1, y1] of ``item`` from the JSON file a ``write_rects`` action
        writes at ``path``, waiting up to ``wait_s`` for it (then ``settle_s`` more, for the frames
        after it to be drawn)."""
        import json
        import time

        path = Path(path)
        for _ in range(int(wait_s / 0.5)):
            if path.exists():
                break
            time.sleep(0.5)
        time.sleep(settle_s)
        return json.loads(path.read_text())[item]

    def dump(self) -> dict:
        import json

        return json.loads((self.tmp / "dump.json").read_text())


def run_reopened(session, tmp_path, display, cache, script, frames: int, timeout: float = 240) -> dict:
    """Run the studio on ``session`` reopened (``--open``) for ``frames`` frames with the ``script`` actions
    and return its state dump (the run must exit 0). Not through the ``run_studio`` fixture: its
    prepared-vs-GUI check fails for any reopened session (viewport and timeline from frame 1), which is
    not what these runs test."""
    return run_scripted(["--open", str(session), "--frames", str(frames)], tmp_path, display, cache, script,
                        timeout=timeout)


def run_scripted(args, tmp_path, display, cache, script, env_extra=None, timeout: float = 240) -> dict:
    """Run the studio with ``args`` and the ``script`` actions in ``tmp_path``; its state dump (it must exit 0)."""
    import json
    import os
    import subprocess
    import sys

    tmp = Path(tmp_path)
    (tmp / "script.json").write_text(json.dumps({"actions": script}))
    env = dict(os.environ, DISPLAY=display, LMM_STUDIO_CONFIG=str(tmp / "config"), LMM_STUDIO_CACHE=str(cache),
               PYTHONPATH=str(ROOT), LP_NUM_THREADS="0", **(env_extra or {}))
    proc = subprocess.run([sys.executable, "-m", "app.cli", *map(str, args), "--script", str(tmp / "script.json"),
                           "--dump-state", str(tmp / "dump.json"), "--no-gamepads"], cwd=tmp, env=env,
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads((tmp / "dump.json").read_text())
