"""Help > Keys and mouse names the pad buttons the input layer binds (it said RB strafe, the binding
and the README R2)."""
from app.command_registry import CommandRegistry
from app.input.manager import PAD_STRAFE_BUTTONS, PAD_WALK_BUTTONS
from app.panels.menu import keys_help


def test_help_names_the_bound_walk_and_strafe_buttons():
    text = keys_help(CommandRegistry())
    assert PAD_STRAFE_BUTTONS == ("r2",) and PAD_WALK_BUTTONS == ("l1", "l2")
    assert "L1/LB or L2/LT walk, R2/RT strafe" in text and "RB strafe" not in text
    readme = (__import__("pathlib").Path(__file__).resolve().parents[3] / "README.md").read_text()
    assert "R2/RT strafes" in readme and "L1/LB or L2/LT walk" in readme
